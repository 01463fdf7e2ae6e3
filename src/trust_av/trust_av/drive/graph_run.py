"""One drive of a person through the node graph in wall mode, recorded to one bag.

Processes (on a leased domain, :class:`~trust_av.graph.processes.Graph`):
``preceding_traffic``, ``planner``, ``ego_plant`` and ``trust_monitor`` as in a whole-graph
wall run (``trust-av shadow --whole-graph``), and ``follower_plant`` in place of
``human_driver`` (:mod:`human_driver_sim.follower_plant_node`). This process serves the page
(:class:`~trust_av.drive.server.DriveServer`), publishes the person's pedal on
``human/accel_cmd`` the moment a sample arrives (from the server's thread), records every
topic (log time = header stamp = wall time) and writes what the person gives into the same
bag, on the same clock:

- ``driver/rating`` (``geometry_msgs/msg/Vector3Stamped``): x the in-drive rating mapped to
  [0, 1] (the monitor's trust scale), y the response time (s), z the rating as given (0-100);
- ``driver/questionnaire`` (``sensor_msgs/msg/JointState``): ``name`` the 12 items
  ``jian_01`` .. ``jian_12`` and ``trust_score``; ``position`` the answers (1-7) and the score
  in [0, 1];
- ``driver/latency`` (``Vector3Stamped``): per acknowledged pedal sample, measured here on
  this process's clock (no time of the page's): x the round trip (sample received ->
  the page's echo of the state frame acknowledging it received, s), y received -> applied
  by the follower plant (s), z applied -> echo received (s). Only sequence numbers this
  process issued and sent are accepted, each once;
- ``driver/model_trust`` (``sensor_msgs/msg/JointState``): every registered trust model's
  trust on the common scale [0, 1] (``name`` the models;
  :func:`~trust_monitor.model_interface.common_trust`), live at each plan pair
  (:class:`~trust_av.drive.link.ModelTrust`);
- ``driver/events`` (``diagnostic_msgs/msg/DiagnosticArray``): the drive's events as the
  status message: ``waiting``, ``start``, ``end`` (``ended_by``), ``page_connected``,
  ``page_lost`` (with the time left: an interruption), ``take_over`` (another tab took the
  control), ``collision`` (the count and the protocol), ``rating_prompt`` (its id).

Only the page's admitted messages reach the drive (:mod:`trust_av.drive.gate`: the
phase, the rate, the pedal's range, open prompts); the refused ones are counted, never
stored (``custom_data`` ``trust_av.drive.refused``: the total, and
``trust_av.drive.refused.<reason>`` per reason, :func:`~trust_av.drive.gate.reason_key`).

The bag's ``custom_data`` (rosbag2 ``metadata.yaml``) holds the study metadata:
participant, condition, alpha, predictor, trace, perturbation and its seed, code version,
seed, status, what ended the drive, the collisions, the refused messages, the latency
percentiles, and what the recording lost (``trust_av.recording.lost``: 0 on a clean
drive; per publisher that lost any, which messages:
:func:`~trust_av.graph.wall_run.loss_entries`). This process records as shadow's
whole-graph run does (:mod:`trust_av.graph.wall_run`): every message taken from the wire
is counted by its publisher's sequence numbers against what each node reports publishing,
and a drive whose recording fell behind keeps every message it holds and names the rest
(:attr:`~trust_av.drive.link.DriveOutcome.losses`) rather than failing.

The drive's clock is the participant's: the drive starts at the Start press
(``trust_av.drive.start_ns``) and ends at ``trust_av.drive.end_ns``. Before the start the
vehicles hold still, the trust monitor waits inactive (it is activated just after the
start, and counts trust from its activation) and the live models take no plan; the
figures read back (:func:`~trust_av.drive.bag_data.read_drive`) are those between the
two times, however long the start screen was read and the nodes took to stop.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from human_driver_sim.follower_plant import FollowerConfig
from preceding_traffic.traces import SpeedTrace
from trust_av.drive.link import DriveLink, DriveOutcome
from trust_av.drive.page_hooks import (
    APPLIED_TOPIC_ABS,
    DRIVER_TOPICS,
    IN_PLACE,
    DrivePage,
    DriveSettings,
)
from trust_av.drive.server import DriveServer
from trust_av.graph.orchestrator import node_specs
from trust_av.graph.processes import NodeSpec
from trust_av.graph.wall_run import RecordedTopic, WallPlan, initial_messages, run_wall
from trust_av.system.closed_loop import equilibrium_start
from trust_av.system.config import RunConfig
from trust_av_common.topics import TOPICS, qualified
from trust_av_common.wall_clock import WallClockConfig

__all__ = ['run_drive']

DRIVE_NODES = ('preceding_traffic', 'planner', 'ego_plant', 'follower_plant', 'trust_monitor')
NOT_PUBLISHED = ('clock', 'sim/start', 'human/plan')
"""Topics of the table that no node of a drive publishes (no lock-step clock; the person
publishes no plan)."""
STARTED_BY_START = ('trust_monitor',)
"""Managed nodes that wait inactive until the participant's start: the monitor's trust is
the drive's, not the start screen's."""


def drive_specs(config: RunConfig, trace_arg: str, trace: SpeedTrace, follower: FollowerConfig,
                rate_hz: float, log_dir: Path) -> list[NodeSpec]:
    """The five node processes of a drive: the whole-graph wall run's, with
    ``follower_plant`` in place of ``human_driver``."""
    initial = equilibrium_start(config.for_trace(trace), trace)
    wall = {'clock_mode': 'wall', 'control_rate_hz': rate_hz}
    specs = [NodeSpec(s.name, s.module,
                      {**s.params, **wall,
                       'jitter_report_path': str(log_dir / f'{s.name}.jitter.json')})
             for s in node_specs(config, trace_arg, trace, initial, log_dir / 'unused.mcap', 0)
             if s.name in DRIVE_NODES]
    specs.append(NodeSpec('follower_plant', 'human_driver_sim.follower_plant_node', {
        **wall, 'jitter_report_path': str(log_dir / 'follower_plant.jitter.json'),
        'initial_position_m': initial.human.position_m,
        'initial_speed_mps': initial.human.speed_mps,
        'vehicle_length_m': config.shared.vehicle_length_m,
        **{name: getattr(follower, name) for name in follower.__dataclass_fields__}}))
    return specs


def drive_plan(config: RunConfig, trace_arg: str, trace: SpeedTrace, bag: Path,
               follower: FollowerConfig, metadata: dict[str, str], rate_hz: float,
               startup_timeout_s: float) -> WallPlan:
    """What a drive runs and records: the graph's topics (from the wire, log time = header
    stamp), then the drive's own, ``human/accel_applied`` from the wire too."""
    from trust_av.graph.bag_qos import offered_qos
    from trust_av_common.ros.qos import record_qos, wall_qos

    clock = WallClockConfig(clock_mode='wall', control_rate_hz=rate_hz)
    recorded = [t for t in TOPICS if t.name not in NOT_PUBLISHED]
    state = offered_qos(wall_qos('STATE', clock, publisher=True))
    topics = [RecordedTopic(qualified(t.name), t.msgtype,
                            offered_qos(wall_qos(t.wall_qos, clock, publisher=True)),
                            record_qos(t.wall_qos)) for t in recorded]
    topics += [RecordedTopic(name, kind, state,
                             record_qos('STATE') if name == APPLIED_TOPIC_ABS else None)
               for name, kind in DRIVER_TOPICS.items()]
    needs = {qualified(t.name): (len([p for p in t.publishers if p != 'human_driver']) or 1, 0)
             for t in recorded}
    needs['/sim/start'] = (1, 3)
    needs['/human/accel_cmd'] = (1, 1)
    needs[APPLIED_TOPIC_ABS] = (1, 1)
    traffic = {(qualified(t.name), 'preceding_traffic') for t in recorded
               if 'preceding_traffic' in t.publishers}
    return WallPlan(
        'drive', lambda log_dir: drive_specs(config, trace_arg, trace, follower, rate_hz,
                                             log_dir),
        config.params_files, bag, topics, needs, DRIVE_NODES, startup_timeout_s,
        custom_data=lambda _graph: metadata, receive_time=False, spin_s=0.005,
        activate_at_start=STARTED_BY_START, deactivate_on_stop=False,
        from_first=traffic,     # the traffic node publishes only after /sim/start
        stop_edge={(qualified(t.name), IN_PLACE.get(n, n)) for t in recorded
                   if t.wall_qos == 'SENSOR' for n in t.publishers},
        initial=initial_messages(recorded, IN_PLACE))


def run_drive(config: RunConfig, trace_arg: str, trace: SpeedTrace, bag: Path, *,
              server: DriveServer, link: DriveLink, follower: FollowerConfig,
              metadata: dict[str, str], duration_s: float, rate_hz: float,
              abandon_after_s: float, start_timeout_s: float, questionnaire: bool,
              questionnaire_timeout_s: float, rating_period_s: float = 15.0,
              on_collision: str = 'continue', page_info: dict[str, Any] | None = None,
              startup_timeout_s: float = 60.0, rating_mode: str = 'prompt') -> DriveOutcome:
    """Run one drive: start the graph, wait for the page's start, drive ``duration_s`` of
    wall time (or until the person has sent nothing for ``abandon_after_s``, or until a
    collision if ``on_collision`` is ``end``), asking a rating every ``rating_period_s``
    (``rating_mode`` prompt) or recording the continuous scale's position that often,
    stop the nodes, ask the questionnaire (if ``questionnaire`` and not abandoned), finish
    the bag. ``page_info`` is shown on the start screen (drive ``number`` ``of``).

    Raises:
        GraphError: the nodes did not connect in time or one died.
        DiskFullError: the disk filled up (the bag is finished with what it holds).
    """
    outcome = DriveOutcome(bag=bag, status='abandoned', driven_s=0.0, counts={})
    settings = DriveSettings(duration_s, rate_hz, abandon_after_s, start_timeout_s,
                             questionnaire, questionnaire_timeout_s, rating_period_s,
                             on_collision, rating_mode, dict(page_info or {}))
    result = run_wall(drive_plan(config, trace_arg, trace, bag, follower, metadata, rate_hz,
                                 startup_timeout_s),
                      DrivePage(config, server, link, settings, outcome))
    outcome.counts, outcome.loops = result.counts, result.loops
    return outcome
