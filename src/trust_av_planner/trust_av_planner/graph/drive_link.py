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

from trust_av_planner.drive.trust_rating import ITEM_NAMES, SCORE_NAME, questionnaire_score

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

    def latency_ms(self) -> dict[str, float]:
        """p50/p99/max of the round trip, and of its graph part, ms (NaN without samples)."""
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
    """What the server's thread and the drive's loop share: the page's messages, the pedal
    publisher and the samples waiting to be acknowledged. Thread-safe."""

    def __init__(self) -> None:
        self.events: queue.SimpleQueue[tuple[dict[str, Any], int]] = queue.SimpleQueue()
        self.lock = threading.Lock()
        self.publisher: Any = None           # human/accel_cmd while a drive runs
        self.pending: dict[int, tuple[int, int]] = {}   # stamp ns -> (seq, arrival ns)
        self.last_input_ns = 0
        self.greet: dict[str, Any] = {}

    def on_message(self, message: dict[str, Any], arrived_ns: int) -> None:
        """Server thread: a pedal sample is published at once; everything goes to the loop."""
        if message['type'] == 'input':
            with self.lock:
                publisher = self.publisher
                self.last_input_ns = arrived_ns
            if publisher is not None:
                try:
                    accel = float(message['accel_mps2'])
                    seq = int(message['seq'])
                except (KeyError, TypeError, ValueError) as err:
                    LOG.warning('a pedal sample without a number dropped: %r (%s)', message,
                                err)
                    return                    # a malformed sample is not a command
                if not np.isfinite(accel):
                    LOG.warning('a non-finite pedal sample dropped: %r', message)
                    return
                msg = _accel_msg(arrived_ns, accel)
                with self.lock:
                    self.pending[arrived_ns] = (seq, arrived_ns)
                publisher.publish(msg)
                self.events.put(({'type': 'command', 'msg': msg}, arrived_ns))
            return
        self.events.put((message, arrived_ns))


def _accel_msg(stamp_ns: int, accel_mps2: float) -> Any:
    """The pedal sample as the follower's command (frame ``human``)."""
    from geometry_msgs.msg import AccelStamped

    from trust_monitor.ros.messages import header
    msg = AccelStamped(header=header(stamp_ns, 'human'))
    msg.accel.linear.x = accel_mps2
    return msg


def vector_msg(stamp_ns: int, x: float, y: float, z: float) -> Any:
    """A ``geometry_msgs/msg/Vector3Stamped`` with no frame (ratings, latency)."""
    from geometry_msgs.msg import Vector3Stamped

    from trust_monitor.common.topics import NO_FRAME
    from trust_monitor.ros.messages import header
    msg = Vector3Stamped(header=header(stamp_ns, NO_FRAME))
    msg.vector.x, msg.vector.y, msg.vector.z = x, y, z
    return msg


def questionnaire_msg(stamp_ns: int, answers: list[int]) -> Any:
    """The questionnaire as a ``sensor_msgs/msg/JointState`` (names and numbers, no text)."""
    from sensor_msgs.msg import JointState

    from trust_monitor.common.topics import NO_FRAME
    from trust_monitor.ros.messages import header
    score = questionnaire_score(answers)
    return JointState(header=header(stamp_ns, NO_FRAME), name=[*ITEM_NAMES, SCORE_NAME],
                      position=[float(a) for a in answers] + [score])


def joint_state_cdr(msg: Any) -> bytes:
    """A JointState serialised exactly (rosbags' CDR): rclpy's serialiser appends the
    alignment padding of the empty trailing ``effort`` array (8 bytes), which rosbags'
    reader refuses as a size mismatch (rclpy reads both)."""
    from trust_av_planner.graph.bag_writer import TYPESTORE

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
