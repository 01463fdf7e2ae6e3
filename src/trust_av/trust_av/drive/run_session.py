"""``trust-av drive``'s session loop: serve the page, run the participant's remaining drives,
write the summary and the comparison (the ROS side of :mod:`trust_av.drive.study`)."""

from __future__ import annotations

import dataclasses
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Protocol

from human_driver_sim.follower_plant import FollowerConfig
from preceding_traffic.sources import load_trace
from trust_av.drive.gate import INPUT_BURST, Gate
from trust_av.drive.graph_run import run_drive
from trust_av.drive.link import DriveLink, code_version
from trust_av.drive.server import DriveServer
from trust_av.drive.sessions import PRACTICE, Condition, DriveRecord
from trust_av.drive.study import (
    DriveConfig,
    comparison_csv,
    comparison_text,
    drive_summary,
    load_drive_settings,
    next_drive,
    plan_session,
    record_drive,
)
from trust_av.drive.trust_rating import registered_models
from trust_av.system.config import RunConfig, load_run_config
from trust_av_common import output_files
from trust_av_common.params import ParamsError
from trust_av_planner.planner_params import check_control_rate

__all__ = ['page_hello', 'page_link', 'run_session']


class SessionOptions(Protocol):
    """What a session reads of ``trust-av drive``'s options
    (:class:`trust_av.cli.drive.DriveOptions`)."""

    @property
    def study(self) -> Path: ...
    @property
    def participant(self) -> str: ...
    @property
    def drive_file(self) -> Path: ...
    @property
    def no_practice(self) -> bool: ...
    @property
    def duration_s(self) -> float | None: ...
    @property
    def port(self) -> int | None: ...
    @property
    def startup_timeout_s(self) -> float: ...
    @property
    def params_files(self) -> tuple[Path, ...]: ...


def _checked_settings(args: SessionOptions) -> tuple[DriveConfig, FollowerConfig,
                                                     list[Condition],
                                                     RunConfig, dict[str, RunConfig]]:
    """The drive file's settings and every condition's run configuration, each checked
    (trace and control rate included) before anything starts."""
    drive, follower, conditions = load_drive_settings(args.drive_file)
    if args.port is not None:
        if not 0 <= args.port <= 65535:
            raise ParamsError(f'--port must be in [0, 65535], got {args.port}')
        drive = dataclasses.replace(drive, port=args.port)
    base = load_run_config(args.params_files)
    rate_hz = base.clock.control_rate_hz
    configs: dict[str, RunConfig] = {}
    for listed in conditions:      # every condition is checked before anything starts
        configs[listed.name] = load_run_config(args.params_files, {'planner': {
            'alpha': listed.alpha, 'predictor': listed.predictor,
            'perturbation': listed.perturbation}})
        load_trace(listed.trace, base.planner.dt_s, base.trace)
        check_control_rate(configs[listed.name].planner, rate_hz)
    return drive, follower, conditions, base, configs


def run_session(args: SessionOptions) -> int:
    """Run the participant's remaining drives (see ``trust-av drive --help``).

    Raises:
        ParamsError: bad settings (named).
        SessionError: bad participant id or a complete session.
        GraphError: the nodes did not connect or one died.
    """
    drive, follower, conditions, base, configs = _checked_settings(args)
    rate_hz = base.clock.control_rate_hz
    by_name = {c.name: c for c in conditions}
    link = page_link(drive, follower, rate_hz)
    # The page's server thread and the recording loop share the GIL: a 1 ms switch interval
    # (Python's default is 5 ms) lets a pedal sample or a state frame through sooner.
    sys.setswitchinterval(0.001)

    def hello() -> dict[str, Any]:
        return page_hello(link, drive, follower, rate_hz, args.participant)
    server = DriveServer(link.on_message, hello, on_event=link.on_event,
                         on_refused=link.gate.refuse, host=drive.host, port=drive.port)
    url = server.start()         # before any file is written: a taken port writes nothing
    try:
        session = plan_session(args.study, args.participant, conditions,
                               practice=drive.practice and not args.no_practice)
    except BaseException:
        server.stop()
        raise
    print(f'drive: participant {args.participant}, order {", ".join(session.order)}; open '
          f'{url}', flush=True)
    models = registered_models(base.trust, dict(base.trust_model_params))
    version = code_version()
    status = 'done'
    try:
        while session.next_condition() is not None:
            index, name, condition, bag, seed = next_drive(args.study, session, by_name,
                                                           drive.seed)
            config = configs[name] if condition is not None else base
            # a *_random perturbation draws its moments from the drive's recorded seed
            config = dataclasses.replace(config, planner=dataclasses.replace(
                config.planner, perturbation_seed=seed))
            trace_name = condition.trace if condition is not None else conditions[0].trace
            trace = load_trace(trace_name, config.planner.dt_s, config.trace)
            duration = args.duration_s or (drive.practice_duration_s if condition is None
                                           else drive.drive_duration_s)
            duration = min(duration, trace.steps * trace.dt_s)
            metadata = _metadata(args.participant, name, index, config, trace_name, version,
                                 seed)
            print(f'drive {index} ({name}): waiting for the participant to start', flush=True)
            outcome = run_drive(config, trace_name, trace, bag, server=server, link=link,
                                follower=follower, metadata=metadata, duration_s=duration,
                                rate_hz=rate_hz, abandon_after_s=drive.abandon_after_s,
                                start_timeout_s=drive.start_timeout_s,
                                questionnaire=condition is not None,
                                questionnaire_timeout_s=drive.questionnaire_timeout_s,
                                rating_period_s=drive.rating_period_s,
                                rating_mode=drive.rating_mode,
                                on_collision=drive.on_collision,
                                page_info=_page_info(session, condition is None),
                                startup_timeout_s=args.startup_timeout_s)
            summary = _summary(bag, condition, outcome, models if condition is not None
                               else [], config.shared.vehicle_length_m, drive.max_lag_s,
                               config.trust_model())
            record_drive(args.study, session, DriveRecord(
                index, name, str(bag.relative_to(args.study)), outcome.status, seed, summary),
                output_files.write_text)
            print('\n'.join(_drive_lines(f'drive {index} ({name})', outcome, summary, bag)),
                  flush=True)
            if outcome.status != 'done':
                status = 'abandoned'
                print(f'drive {index} ({name}): the participant stopped sending; the session '
                      'stops here. Run the same command to resume with this condition.',
                      flush=True)
                break
    finally:
        server.send({'type': 'phase', 'phase': 'finished' if status == 'done' else 'paused'})
        server.stop()
    all_rows: list[dict[str, Any]] = [
        {'drive': r.index, 'condition': r.condition, **c}
        for r in session.drives if r.status == 'done' for c in r.summary.get('comparison', [])]
    directory = args.study / args.participant
    output_files.write_text(directory / 'comparison.csv', comparison_csv(all_rows))
    print('\n'.join(comparison_text(all_rows) or ['no ratings to compare yet']))
    print(f'summary: {directory / "summary.csv"}; comparison: {directory / "comparison.csv"}')
    return 0


def _metadata(participant: str, name: str, index: int, config: Any, trace_name: str,
              version: str, seed: int) -> dict[str, str]:
    """The study metadata of one drive (its bag's ``custom_data``)."""
    return {'trust_av.participant': participant,
            'trust_av.condition': name, 'trust_av.drive': str(index),
            'trust_av.alpha': f'{config.planner.alpha:g}',
            'trust_av.predictor': config.planner.predictor,
            'trust_av.perturbation': config.planner.perturbation,
            'trust_av.perturbation_seed': str(config.planner.perturbation_seed),
            'trust_av.trace': trace_name, 'trust_av.code_version': version,
            'trust_av.seed': str(seed)}


def page_link(drive: DriveConfig, follower: FollowerConfig, rate_hz: float) -> DriveLink:
    """The session's link to its page: a gate with the study's pedal range, control rate and
    rating mode."""
    return DriveLink(Gate(rate_hz, follower.accel_min_mps2, follower.accel_max_mps2,
                          continuous=drive.rating_mode == 'continuous'))


def page_hello(link: DriveLink, drive: DriveConfig, follower: FollowerConfig,
               rate_hz: float, participant: str) -> dict[str, Any]:
    """What a page is told when it connects: the settings and where the session is (a
    reopened tab shows the phase, the open rating prompt or the continuous scale's
    position; frames give the time left)."""
    scale = link.gate.trust_now()
    return {'type': 'hello', 'control_rate_hz': rate_hz, 'input_burst': INPUT_BURST,
            'participant': participant,
            'accel_max_mps2': follower.accel_max_mps2,
            'accel_min_mps2': follower.accel_min_mps2,
            'on_collision': drive.on_collision, 'rating_mode': drive.rating_mode,
            'prompts': link.gate.open_prompts(), 'scale': None if scale is None else scale[0],
            **{k: v for k, v in link.greet.items() if k != 'type'}}


def _page_info(session: Any, practice: bool) -> dict[str, Any]:
    """What the start screen says: a practice drive, or drive ``number`` ``of``."""
    done = sum(1 for d in session.drives if d.status == 'done' and d.condition != PRACTICE)
    return {'practice': practice, 'number': done + 1, 'of': len(session.order)}


def _summary(bag: Path, condition: Any, outcome: Any, models: Any, vehicle_length_m: float,
             max_lag_s: float, monitor_model: Any) -> dict[str, Any]:
    """The drive's summary (:func:`~trust_av.drive.study.drive_summary`; a drive never
    started has nothing to summarise), its comparison rows and its recording's losses."""
    if outcome.driven_s > 0:
        summary, rows = drive_summary(bag, condition, outcome, models, vehicle_length_m,
                                      max_lag_s, monitor_model)
    else:
        summary, rows = {'driven_s': 0.0}, []
    summary['comparison'] = rows
    summary.update(_recording_losses(outcome.losses))
    return summary


def _drive_lines(drive: str, outcome: Any, summary: dict[str, Any], bag: Path) -> list[str]:
    """What the experimenter is told after a drive (a second line only if the recording
    lost messages)."""
    lines = [f'{drive}: {outcome.status} after {outcome.driven_s:.1f} s, '
             f'{outcome.collisions} collisions, {len(outcome.ratings)} ratings, '
             f'{sum(outcome.refused.values())} messages refused, latency p99 '
             f'{summary.get("latency_p99_ms", "-")} ms; {bag}']
    if summary['recording_lost']:
        lines.append(f'{drive}: the recording lost {summary["recording_lost"]} messages '
                     f'({"; ".join(summary["recording_losses"])}); the bag holds the rest and '
                     'names them in its metadata (trust_av.recording.lost)')
    return lines


def _recording_losses(losses: Sequence[Any]) -> dict[str, Any]:
    """The drive summary's account of what the recording lost: ``recording_lost`` the
    messages (0 on a clean drive), ``recording_losses`` which, per publisher
    (:meth:`~trust_av.graph.publication_ledger.Lost.describe`)."""
    return {'recording_lost': sum(loss.count for loss in losses),
            'recording_losses': [loss.describe() for loss in losses]}
