"""Read a graph recording back into the simulator's per-step records (with rosbags).

The in-process loop and the node graph are compared, and graph runs are summarised, through
the same :class:`~trust_av.system.metrics.StepRecord`. Reading uses ``rosbags``
(``AnyReader``), a reader independent of the recorder's ``mcap`` writer.
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import Any

from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from trust_av.errors import TrustAvAppError
from trust_av.system.metrics import StepRecord
from trust_av_common.topics import qualified

__all__ = ['TYPESTORE', 'message_stamp', 'read_topics', 'records_from_bag']

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)


def _ns(stamp: Any) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def message_stamp(msg: Any) -> Any:
    """A recorded message's stamp: a Clock's time, a header's stamp, or (``tf``, markers)
    the first element's header stamp."""
    if hasattr(msg, 'clock'):
        return msg.clock
    if hasattr(msg, 'header'):
        return msg.header.stamp
    elements = msg.transforms if hasattr(msg, 'transforms') else msg.markers
    return elements[0].header.stamp


def read_topics(path: Path) -> dict[str, dict[int, Any]]:
    """Topic -> stamp (ns) -> deserialised message (the last of a stamp: ``tf`` holds three
    per stamp, one per vehicle)."""
    out: dict[str, dict[int, Any]] = defaultdict(dict)
    try:
        with AnyReader([path], default_typestore=TYPESTORE) as reader:
            for connection, _log_time, raw in reader.messages():
                msg = reader.deserialize(raw, connection.msgtype)
                out[connection.topic][_ns(message_stamp(msg))] = msg
    except Exception as err:  # rosbags raises several unrelated types for a bad file
        raise TrustAvAppError(f'{path}: cannot read the recording ({err})') from err
    return out


def _accels(msg: Any, where: str, *, may_be_empty: bool = False) -> tuple[float, ...]:
    """The accelerations of a recorded plan, one per point.

    Raises:
        TrustAvAppError: a plan without points (unless ``may_be_empty``), or a point
            without an acceleration (not one of the graph's plans: e.g. another node's on
            the same topic).
    """
    if (not msg.points and not may_be_empty) or any(len(p.accelerations) < 1
                                                    for p in msg.points):
        raise TrustAvAppError(f'{where}: a plan without accelerations (not one the graph '
                              'publishes: another publisher on the topic?)')
    return tuple(float(p.accelerations[0]) for p in msg.points)


def records_from_bag(path: Path, namespace: str = '/') -> list[StepRecord]:
    """One :class:`StepRecord` per complete step of a graph recording, in time order.

    A step is complete when the planner's, driver's and monitor's outputs for its stamp are
    all in the bag; a recording cut short by a fault yields the steps before the fault.
    ``namespace`` is the run's (its topics are read: ``/car1/ego/odom`` for ``/car1``).
    """
    topics = read_topics(path)

    def at(name: str, stamp: int) -> Any:
        return topics[qualified(name, namespace)][stamp]

    records = []
    for ns in sorted(topics[qualified('ego/planner_status', namespace)]):
        try:
            traffic = at('preceding_vehicle/odom', ns)
            ego = at('ego/odom', ns)
            human = at('human/odom', ns)
            plan = at('ego/plan', ns)
            expected = at('ego/expected_plan', ns)
            human_plan = at('human/plan', ns)
            trust = at('trust_monitor/trust', ns)
            status = {kv.key: kv.value for kv in at('ego/planner_status', ns).status[0].values}
            driver = {kv.key: kv.value for kv in at('human/driver_status', ns).status[0].values}
        except KeyError:
            break  # the first incomplete step: the recording ends here
        ego_x, ego_v = ego.pose.pose.position.x, ego.twist.twist.linear.x
        human_x, human_v = human.pose.pose.position.x, human.twist.twist.linear.x
        traffic_x = traffic.pose.pose.position.x
        plans = {name: _accels(msg, f'{path}: {qualified(name, namespace)} at t = '
                                    f'{ns * 1e-9:g} s', may_be_empty=name == 'ego/expected_plan')
                 for name, msg in (('ego/plan', plan), ('ego/expected_plan', expected),
                                   ('human/plan', human_plan))}
        records.append(StepRecord(
            t_s=ns * 1e-9, traffic_position_m=traffic_x,
            traffic_speed_mps=traffic.twist.twist.linear.x,
            av_position_m=ego_x, av_speed_mps=ego_v,
            av_gap_m=float(status['gap_m']), human_position_m=human_x,
            human_speed_mps=human_v, human_gap_m=float(driver['gap_m']),
            av_accel_mps2=plans['ego/plan'][0], human_accel_mps2=plans['human/plan'][0],
            av_plan_mps2=plans['ego/plan'], expected_plan_mps2=plans['ego/expected_plan'],
            human_plan_mps2=plans['human/plan'], explicability=trust.vector.x,
            performance=trust.vector.y, trust=trust.vector.z,
            explicability_max=float(status['explicability_max']),
            solver_status=status['status'], solver_success=status['success'] == 'True',
            solver_iterations=int(status['iterations']),
            solve_time_s=float(status['solve_time_s']), driver_status=driver['status'],
            driver_success=driver['success'] == 'True',
            driver_solve_time_s=float(driver['solve_time_s'])))
    return records
