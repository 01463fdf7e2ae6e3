"""What one drive shares between the page server's thread and the recording loop
(:class:`DriveLink`), what it gave (:class:`DriveOutcome`) and the messages the drive writes
for the person (pedal, ratings, latency, questionnaire)."""

from __future__ import annotations

import logging
import queue
import subprocess
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from trust_av.drive.gate import Gate
from trust_av.drive.trust_rating import ITEM_NAMES, SCORE_NAME, questionnaire_score

__all__ = ['DriveLink', 'DriveOutcome', 'ModelTrust', 'code_version', 'event_msg',
           'joint_state_cdr', 'questionnaire_msg', 'vector_msg']

LOG = logging.getLogger(__name__)


@dataclass
class DriveOutcome:
    """What one drive gave."""

    bag: Path
    status: str
    driven_s: float
    counts: dict[str, int]
    latency_s: list[tuple[float, float, float]] = field(default_factory=list)
    ratings: list[tuple[float, float]] = field(default_factory=list)
    questionnaire: list[int] | None = None
    loops: dict[str, Any] = field(default_factory=dict)
    collisions: int = 0
    ended_by: str = ''
    refused: dict[str, int] = field(default_factory=dict)
    events: list[tuple[float, str]] = field(default_factory=list)
    losses: tuple[Any, ...] = ()
    """What the recording lost (:class:`~trust_av.graph.publication_ledger.Lost`; none on a
    clean drive)."""

    def latency_ms(self) -> dict[str, float]:
        """p50/p99/max of the round trip (pedal sample received here -> the page's echo of
        its acknowledgement received here), and of its graph part, ms (NaN without
        samples)."""
        if not self.latency_s:
            return {'round_trip_p50_ms': float('nan'), 'round_trip_p99_ms': float('nan'),
                    'round_trip_max_ms': float('nan'), 'graph_p99_ms': float('nan'),
                    'samples': 0}
        trip = np.array([a for a, _, _ in self.latency_s]) * 1e3
        graph = np.array([b for _, b, _ in self.latency_s]) * 1e3
        return {'round_trip_p50_ms': float(np.percentile(trip, 50)),
                'round_trip_p99_ms': float(np.percentile(trip, 99)),
                'round_trip_max_ms': float(trip.max()),
                'graph_p99_ms': float(np.percentile(graph, 99)), 'samples': len(trip)}


def code_version() -> str:
    """The repository's commit (``git describe --always --dirty``), or ``unknown``."""
    try:
        out = subprocess.run(['git', 'describe', '--always', '--dirty'], capture_output=True,
                             text=True, timeout=5, cwd=Path(__file__).parent, check=False)
    except OSError:
        return 'unknown'
    return out.stdout.strip() or 'unknown'




class DriveLink:
    """What the server's thread and the drive's loop share: the page's admitted messages,
    the pedal publisher, the samples waiting to be acknowledged and the message policy
    (:class:`~trust_av.drive.gate.Gate`). Thread-safe."""

    def __init__(self, gate: Gate) -> None:
        self.gate = gate
        self.events: queue.SimpleQueue[tuple[dict[str, Any], int]] = queue.SimpleQueue()
        self.lock = threading.Lock()
        self.publisher: Any = None           # human/accel_cmd while a drive runs
        self.pending: dict[int, tuple[int, int]] = {}   # stamp ns -> (seq, arrival ns)
        self.last_input_ns = 0
        self.greet: dict[str, Any] = {}

    def on_message(self, message: dict[str, Any], arrived_ns: int) -> None:
        """Server thread: a message of the controlling page. One that does not fit the
        phase is refused and counted; an admitted pedal sample is rate-limited (on the
        page's clock, as far as it does not run ahead of this one), clipped to the pedal's
        range and published at once, stamped with its arrival; everything else goes to the
        loop."""
        if not self.gate.admit(message):
            return
        if message['type'] != 'input':
            self.events.put((message, arrived_ns))
            return
        with self.lock:
            publisher = self.publisher
        if publisher is None:
            self.gate.refuse('input before the drive started')
            return
        sample = self.gate.sample(message, arrived_ns)
        if sample is None:
            return
        msg = _accel_msg(arrived_ns, sample.accel_mps2)
        with self.lock:
            self.last_input_ns = arrived_ns
            self.pending[arrived_ns] = (sample.seq, arrived_ns)
        publisher.publish(msg)
        self.events.put(({'type': 'command', 'msg': msg, 'clipped': sample.clipped},
                         arrived_ns))

    def on_event(self, kind: str, now_ns: int) -> None:
        """Server thread: the controlling page connected, was lost or was taken over (a
        page that now drives has a clock of its own: the gate anchors it anew)."""
        if kind in ('page_connected', 'take_over'):
            self.gate.new_page()
        self.events.put(({'type': 'event', 'event': kind}, now_ns))


def _accel_msg(stamp_ns: int, accel_mps2: float) -> Any:
    """The pedal sample as the follower's command (frame ``human``)."""
    from geometry_msgs.msg import AccelStamped

    from trust_av_common.ros.messages import header
    msg = AccelStamped(header=header(stamp_ns, 'human'))
    msg.accel.linear.x = accel_mps2
    return msg


def vector_msg(stamp_ns: int, x: float, y: float, z: float) -> Any:
    """A ``geometry_msgs/msg/Vector3Stamped`` with no frame (ratings, latency)."""
    from geometry_msgs.msg import Vector3Stamped

    from trust_av_common.ros.messages import header
    from trust_av_common.topics import NO_FRAME
    msg = Vector3Stamped(header=header(stamp_ns, NO_FRAME))
    msg.vector.x, msg.vector.y, msg.vector.z = x, y, z
    return msg


def questionnaire_msg(stamp_ns: int, answers: list[int]) -> Any:
    """The questionnaire as a ``sensor_msgs/msg/JointState`` (names and numbers, no text)."""
    from sensor_msgs.msg import JointState

    from trust_av_common.ros.messages import header
    from trust_av_common.topics import NO_FRAME
    score = questionnaire_score(answers)
    return JointState(header=header(stamp_ns, NO_FRAME), name=[*ITEM_NAMES, SCORE_NAME],
                      position=[float(a) for a in answers] + [score])


def joint_state_cdr(msg: Any) -> bytes:
    """A JointState serialised exactly (rosbags' CDR): rclpy's serialiser appends the
    alignment padding of the empty trailing ``effort`` array (8 bytes), which rosbags'
    reader refuses as a size mismatch (rclpy reads both)."""
    from trust_av.graph.bag_writer import TYPESTORE

    kind = 'sensor_msgs/msg/JointState'
    header = TYPESTORE.types['std_msgs/msg/Header']
    stamp = TYPESTORE.types['builtin_interfaces/msg/Time']
    plain = TYPESTORE.types[kind](
        header=header(stamp=stamp(sec=msg.header.stamp.sec, nanosec=msg.header.stamp.nanosec),
                      frame_id=msg.header.frame_id),
        name=list(msg.name), position=np.array(msg.position, dtype=np.float64),
        velocity=np.array(msg.velocity, dtype=np.float64),
        effort=np.array(msg.effort, dtype=np.float64))
    return bytes(TYPESTORE.serialize_cdr(plain, kind))


class ModelTrust:
    """Every registered trust model run live on the AV's plans as the drive records them
    (each model by the monitor's own :class:`~trust_monitor.paper_trust.TrustEstimator`,
    each update scaled by the time since the previous plan pair), so a drive's bag holds
    every model's trust beside the monitor's.

    Args:
        config: the run's shared trust parameters.
        values: the params files' values of the models' own parameters.
    """

    def __init__(self, config: Any, values: dict[str, Any]) -> None:
        import dataclasses

        from trust_av_common.registry import names
        from trust_monitor.model_interface import TRUST_MODELS, make_trust_model
        from trust_monitor.paper_trust import TrustEstimator

        self.names = list(names(TRUST_MODELS))
        self.estimators = []
        for name in self.names:
            each = dataclasses.replace(config, trust_model=name)
            self.estimators.append(TrustEstimator(each, make_trust_model(each, values)))
        self.plans: dict[str, dict[int, list[float]]] = {'plan': {}, 'expected': {}}
        self.last_ns: int | None = None
        self.period_s = 0.1

    def add(self, kind: str, stamp_ns: int, plan: list[float]) -> list[float] | None:
        """A plan (``kind`` ``plan`` or ``expected``) of step ``stamp_ns``; every model's
        trust on the common scale [0, 1]
        (:func:`~trust_monitor.model_interface.common_trust`: the model's declared
        ``trust_range``) once both plans of the step are in, else None."""
        self.plans[kind][stamp_ns] = plan
        other = self.plans['expected' if kind == 'plan' else 'plan']
        if stamp_ns not in other:
            return None
        plan_r, expected = self.plans['plan'].pop(stamp_ns), self.plans['expected'].pop(
            stamp_ns)
        for table in self.plans.values():
            for old in [s for s in table if s < stamp_ns]:
                del table[old]
        if self.last_ns is not None and stamp_ns > self.last_ns:
            self.period_s = (stamp_ns - self.last_ns) / 1e9
        self.last_ns = stamp_ns
        from trust_monitor.model_interface import common_trust
        trust: list[float] = []   # on the common scale (common_trust: UnitTrust)
        for estimator in self.estimators:
            estimator.step(plan_r, expected, self.period_s)
            trust.append(common_trust(estimator.model, estimator.state))
        return trust

    def message(self, stamp_ns: int, trust: list[float]) -> Any:
        """Every model's trust as a ``sensor_msgs/msg/JointState`` (``name`` the models,
        ``position`` their trust on the common scale [0, 1])."""
        from sensor_msgs.msg import JointState

        from trust_av_common.ros.messages import header
        from trust_av_common.topics import NO_FRAME
        return JointState(header=header(stamp_ns, NO_FRAME), name=list(self.names),
                          position=list(trust))


def event_msg(stamp_ns: int, event: str, values: dict[str, str]) -> Any:
    """A drive event (start, end, page connected or lost, take-over, collision, rating
    prompt) as a ``diagnostic_msgs/msg/DiagnosticArray``: status ``drive``, message the
    event, values its details."""
    from trust_av_common.ros.messages import diagnostics
    return diagnostics(stamp_ns, 'drive', event not in ('page_lost', 'collision'), event,
                       values)
