"""A participant's whole session: settings, the drives in counterbalanced order, resume,
the per-drive comparison of ratings with the trust models and the summary table.

Settings live in ``config/drive.yaml`` (ROS 2 params-file format, section ``/**/drive``):
the scalar ones in :class:`DriveConfig` and :class:`~human_driver_sim.follower_plant.
FollowerConfig`, the conditions as four arrays of equal length (``condition_names``,
``condition_alphas``, ``condition_predictors``, ``condition_traces``).
"""

from __future__ import annotations

import csv
import dataclasses
import io
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from human_driver_sim.follower_plant import FollowerConfig
from trust_av.drive.sessions import (
    DONE,
    PRACTICE,
    Condition,
    DriveRecord,
    Session,
    SessionError,
    check_condition_name,
    drive_dir,
    enrol,
    save_session,
)
from trust_av.drive.trust_rating import (
    RatingError,
    TrustModel,
    agreement_lines,
    compare,
)
from trust_av_common.params import ParamsError, build_config, check_fields, param
from trust_av_planner.perturbations import LIBRARY
from trust_monitor import model_interface

__all__ = ['DriveConfig', 'comparison_csv', 'comparison_text', 'conditions_from', 'drive_summary',
           'load_drive_settings', 'next_drive', 'plan_session', 'record_drive', 'summary_csv']

SECTION = '/drive'
SEED_MODULUS = 2**32
"""Drive k's seed is the study's seed + k modulo this (a planner ``perturbation_seed``)."""
"""The node name the drive's settings are read for (``/**/drive`` or ``/drive``)."""
CONDITION_KEYS = ('condition_names', 'condition_alphas', 'condition_predictors',
                  'condition_traces')
PERTURBATION_KEY = 'condition_perturbations'
"""Optional fifth array: each condition's perturbation (default: none for every one)."""


@dataclass(frozen=True)
class DriveConfig:
    """The study's settings (``config/drive.yaml``)."""

    drive_duration_s: float = param('wall time of one drive', unit='s', low=1.0, default=120.0,
    high=86400.0)
    practice: bool = param('start each new session with a practice drive', default=True)
    practice_duration_s: float = param('wall time of the practice drive', unit='s', low=1.0,
                                       default=60.0, high=86400.0)
    rating_period_s: float = param('the in-drive trust rating is asked (prompt) or recorded '
                                   '(continuous) this often', unit='s', low=1.0, default=15.0,
                                   high=3600.0)
    rating_mode: str = param('how the in-drive trust rating is taken: a card asks for it '
                             'every rating_period_s (prompt), or a scale stays on screen, '
                             'set on the start screen and moved whenever trust changes, and '
                             'its position is recorded at the start and every '
                             'rating_period_s (continuous)', choices=('prompt', 'continuous'),
                             default='prompt')
    abandon_after_s: float = param('a drive ends as abandoned when no pedal sample came for '
                                   'this long', unit='s', low=0.5, default=10.0, high=3600.0)
    start_timeout_s: float = param("how long a drive waits for the participant's start",
                                   unit='s', low=1.0, default=900.0, high=86400.0)
    questionnaire_timeout_s: float = param('how long the questionnaire waits for its answers',
                                           unit='s', low=1.0, default=900.0, high=86400.0)
    host: str = param('address the page is served on (127.0.0.1: this machine only)',
                      default='127.0.0.1')
    port: int = param('TCP port of the page (0: any free port)', low=0, high=65535,
                      default=8765)
    seed: int = param("the study's seed, recorded with every drive (drive k: seed + k, modulo "
                      "2**32: the perturbation seed's range)", low=0, default=0,
                      high=SEED_MODULUS - 1)
    max_lag_s: float = param('largest lag tried when comparing ratings with a model',
                             unit='s', low=0.0, default=10.0, high=600.0)
    on_collision: str = param("the protocol at a collision (the participant's car stops at "
                              "the AV's rear bumper): continue the drive, or end it",
                              choices=('continue', 'end'), default='continue')

    def __post_init__(self) -> None:
        check_fields(self)


def conditions_from(values: dict[str, Any], where: str) -> list[Condition]:
    """The conditions from the four arrays of the settings.

    Raises:
        ParamsError: a missing array, arrays of different lengths, or a bad value (named).
    """
    missing = [k for k in CONDITION_KEYS if k not in values]
    if missing:
        raise ParamsError(f'{where}: missing {", ".join(missing)}')
    names, alphas, predictors, traces = (values[k] for k in CONDITION_KEYS)
    if not all(isinstance(v, list) for v in (names, alphas, predictors, traces)) \
            or len({len(names), len(alphas), len(predictors), len(traces)}) != 1 or not names:
        raise ParamsError(f'{where}: {", ".join(CONDITION_KEYS)} must be non-empty arrays of '
                          'one length')
    perturbations = values.get(PERTURBATION_KEY, ['none'] * len(names))
    if not isinstance(perturbations, list) or len(perturbations) != len(names):
        raise ParamsError(f'{where}: {PERTURBATION_KEY} must be an array of one length with '
                          f'{", ".join(CONDITION_KEYS)}')
    out = []
    for name, alpha, predictor, trace, perturbation in zip(
            names, alphas, predictors, traces, perturbations, strict=True):
        try:
            check_condition_name(name)
        except SessionError as err:
            raise ParamsError(f'{where}: condition_names: {err}') from err
        if names.count(name) > 1:
            raise ParamsError(f'{where}: condition_names: {name!r} is listed twice')
        if not isinstance(alpha, (int, float)) or isinstance(alpha, bool) \
                or not 0.0 <= alpha <= 1.0:
            raise ParamsError(f'{where}: condition {name!r}: alpha must be in [0, 1], got '
                              f'{alpha!r}')
        if perturbation not in LIBRARY:
            raise ParamsError(f'{where}: condition {name!r}: perturbation must be one of '
                              f'{list(LIBRARY)}, got {perturbation!r}')
        for key, value in (('condition_predictors', predictor), ('condition_traces', trace)):
            if not isinstance(value, str) or not value:
                raise ParamsError(f'{where}: condition {name!r}: {key} holds {value!r}, not a '
                                  'name')
        out.append(Condition(name, float(alpha), predictor, trace,
                             str(perturbation)))
    return out


def load_drive_settings(path: Path) -> tuple[DriveConfig, FollowerConfig, list[Condition]]:
    """Read the study's settings file.

    Raises:
        ParamsError: unreadable, an unknown key, a bad value (one line naming it).
    """
    from trust_av_common.param_layers import layered_params, read_layer

    values = dict(layered_params([read_layer(path)], SECTION))
    known = {f.name for c in (DriveConfig, FollowerConfig) for f in dataclasses.fields(c)}
    unknown = sorted(set(values) - known - set(CONDITION_KEYS) - {PERTURBATION_KEY})
    if unknown:
        raise ParamsError(f'{path}: unknown parameter(s) {", ".join(unknown)}')
    return (build_config(DriveConfig, values), build_config(FollowerConfig, values),
            conditions_from(values, str(path)))


SUMMARY_FIELDS = ('drive', 'condition', 'alpha', 'predictor', 'trace', 'perturbation',
                  'status', 'driven_s',
                  'ratings', 'mean_rating', 'final_monitor_trust', 'questionnaire_score',
                  'min_gap_m', 'collisions', 'ended_by', 'refused_messages', 'latency_p50_ms',
                  'latency_p99_ms', 'latency_samples', 'recording_lost', 'bag')


def summary_row(record: DriveRecord) -> dict[str, Any]:
    """One row of the participant's summary table."""
    return {'drive': record.index, 'condition': record.condition, 'bag': record.bag,
            'status': record.status, **record.summary}


def summary_csv(session: Session) -> str:
    """The participant's summary table (CSV, one row per drive)."""
    out = io.StringIO()
    writer = csv.DictWriter(out, SUMMARY_FIELDS, extrasaction='ignore', lineterminator='\n')
    writer.writeheader()
    for record in session.drives:
        writer.writerow(summary_row(record))
    return out.getvalue()


def drive_summary(bag: Path, condition: Condition | None, outcome: Any,
                  models: Sequence[tuple[str, TrustModel]], vehicle_length_m: float,
                  max_lag_s: float, monitor_model: model_interface.TrustModel | None = None
                  ) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """The summary of one recorded drive and its comparison rows (one per model).

    Reads the drive back from its bag (:func:`~trust_av.drive.bag_data.read_drive`),
    so the numbers are the recording's. ``final_monitor_trust`` is on the common scale
    [0, 1], the ratings' (:func:`~trust_monitor.model_interface.unit_trust` of the trust
    model the monitor ran, ``monitor_model``; without it, the trust as published).
    """
    from trust_av.drive.bag_data import read_drive

    drive = read_drive(bag)
    you, av = drive.odometry['/human/odom'], drive.odometry['/ego/odom']
    # the gap only while both are recorded: as the nodes stop, the AV's odometry may end
    # before the follower's, and the AV held at its last position is not where it was
    if len(av):
        you = you[(you[:, 0] >= av[0, 0]) & (you[:, 0] <= av[-1, 0])]
    gaps = (np.interp(you[:, 0], av[:, 0], av[:, 1]) - vehicle_length_m - you[:, 1]) \
        if len(you) and len(av) else np.array([])
    latency = outcome.latency_ms()
    monitor = drive.series.monitor_trust
    summary = {
        'alpha': condition.alpha if condition else '', 'predictor':
        condition.predictor if condition else '', 'trace': condition.trace if condition else '',
        'perturbation': condition.perturbation if condition else '',
        'driven_s': round(outcome.driven_s, 3), 'ratings': len(drive.ratings),
        'mean_rating': round(float(np.mean(drive.ratings)), 4) if len(drive.ratings) else '',
        'final_monitor_trust': round(float(
            monitor[-1] if monitor_model is None
            else model_interface.unit_trust(monitor_model, monitor[-1])), 4)
        if len(monitor) and math.isfinite(monitor[-1]) else '',
        'questionnaire_score': round(drive.questionnaire[-1], 4) if drive.questionnaire else '',
        'min_gap_m': round(float(gaps.min()), 3) if len(gaps) else '',
        'collisions': outcome.collisions, 'ended_by': outcome.ended_by,
        'refused_messages': sum(outcome.refused.values()), 'refused': dict(outcome.refused),
        'latency_p50_ms': round(latency['round_trip_p50_ms'], 2),
        'latency_p99_ms': round(latency['round_trip_p99_ms'], 2),
        'latency_samples': latency['samples']}
    rows: list[dict[str, Any]] = []
    if len(drive.ratings) and len(drive.series.times_s):
        try:
            for a in compare(drive.rating_times_s, drive.ratings, drive.series, models,
                             max_lag_s=max_lag_s):
                rows.append(dataclasses.asdict(a))
        except RatingError:
            rows = []
    return summary, rows


COMPARISON_FIELDS = ('drive', 'condition', 'model', 'ratings', 'rmse', 'correlation',
                     'best_lag_s', 'rmse_at_best_lag')


def comparison_csv(rows: Sequence[dict[str, Any]]) -> str:
    """Ratings vs every model, every drive (CSV)."""
    out = io.StringIO()
    writer = csv.DictWriter(out, COMPARISON_FIELDS, extrasaction='ignore', lineterminator='\n')
    writer.writeheader()
    for row in rows:
        writer.writerow({k: (f'{v:.6g}' if isinstance(v, float) else v)
                         for k, v in row.items()})
    return out.getvalue()


def comparison_text(rows: Sequence[dict[str, Any]]) -> list[str]:
    """The comparison as printed at the end of a session."""
    from trust_av.drive.trust_rating import Agreement

    lines: list[str] = []
    for drive in sorted({(r['drive'], r['condition']) for r in rows}):
        lines.append(f'drive {drive[0]} ({drive[1]}):')
        lines += ['  ' + line for line in agreement_lines(
            [Agreement(**{k: r[k] for k in Agreement.__dataclass_fields__})
             for r in rows if (r['drive'], r['condition']) == drive])]
    return lines


def plan_session(study: Path, participant: str, conditions: list[Condition],
                 practice: bool) -> Session:
    """Enrol (or resume) the participant; refuse a finished session.

    Raises:
        SessionError: bad id or conditions, or the session is complete.
    """
    session = enrol(study, participant, conditions, practice=practice)
    if session.next_condition() is None:
        raise SessionError(f'participant {participant} has completed every condition '
                           f'({study / participant / "summary.csv"})')
    return session


def next_drive(study: Path, session: Session, by_name: dict[str, Condition],
               seed: int) -> tuple[int, str, Condition | None, Path, int]:
    """(index, condition name, condition or None for the practice, bag path, seed) of the
    session's next drive (its seed: ``seed`` + index modulo :data:`SEED_MODULUS`, so any seed
    the settings accept gives every drive a valid one)."""
    name = session.next_condition()
    assert name is not None
    index = len(session.drives) + 1
    return (index, name, by_name.get(name), drive_dir(study, session.participant, index, name),
            (seed + index) % SEED_MODULUS)


def record_drive(study: Path, session: Session, record: DriveRecord,
                 write_text: Callable[[Path, str], None]) -> None:
    """Add a drive's outcome to the session and rewrite the session file and summary."""
    session.drives.append(record)
    if record.condition == PRACTICE and record.status == DONE:
        session.practice_done = True
    save_session(study, session)
    write_text(study / session.participant / 'summary.csv', summary_csv(session))

