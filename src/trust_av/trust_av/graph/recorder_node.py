"""``recorder`` node (``ros2 run trust_av_planner recorder``): every topic of the graph that
lists it as a subscriber, raw as it came over DDS, into one rosbag2 bag directory
(:class:`trust_av.graph.bag_writer.BagWriter`: metadata.yaml + MCAP, one chunk per
step).

- **Ready**: it publishes ``recorder/status`` (latched) with ``state: ready`` only once every
  subscription has matched its publishers, so a run started after that loses nothing.
- **Steps**: in lock-step a chunk is written at every ``clock`` (the step authority's tick);
  in wall mode every ``flush_period_s``. The status carries the steps written (at most
  twice a second): the orchestrator's progress, without a per-step subscriber of its own.
- **Back-pressure** (lock-step): it acknowledges the complete steps it holds on
  ``recorder/ack`` (every :data:`~trust_av_common.record_window.ACK_EVERY_STEPS`
  steps); the step authority runs at most a window of steps ahead of it, so a recorder that
  is suspended or slow holds the graph back instead of losing messages
  (:mod:`trust_av_common.record_window` says why nothing can be lost).
- **Slow disk** (tests only): the environment variable :data:`WRITE_DELAY_ENV` makes every
  chunk write sleep that many seconds first.
- **End**: it finishes the bag and exits by itself once it holds every message of
  ``expected_steps`` steps (0: record until stopped), or of the steps up to a collision (a
  step status, ``ego/planner_status`` or ``human/driver_status``, with a ``gap_m`` at or
  below 0 m: the step authority starts no step after it); on SIGINT/SIGTERM/SIGHUP, or when the
  orchestrator that started it dies, it takes what is still queued and finishes the bag.
  A full disk finishes the bag with every complete step, one line on stderr, exit code 3.
"""

from __future__ import annotations

import functools
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import yaml
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from std_msgs.msg import UInt64

from trust_av.errors import TrustAvAppError
from trust_av.graph.bag_qos import offered_profiles
from trust_av.graph.bag_writer import EXIT_DISK_FULL, MAX_CHUNKS_PER_FILE, BagWriter
from trust_av_common.params import check_fields, param
from trust_av_common.record_window import ACK_EVERY_STEPS, ACK_TOPIC, recorded_topics
from trust_av_common.ros.messages import diagnostics, message_class, status_gap_m
from trust_av_common.ros.parameters import declare_config
from trust_av_common.ros.qos import QOS
from trust_av_common.ros.spin import spin_node
from trust_av_common.topics import TOPICS
from trust_av_common.wall_clock import WallClockConfig

__all__ = ['READY_CHECK_PERIOD_S', 'main']

STATUS_TOPIC = 'recorder/status'
STATUS_PERIOD_S = 0.5
READY_CHECK_PERIOD_S = 0.05
WRITE_DELAY_ENV = 'TRUST_AV_TEST_WRITE_DELAY_S'
"""Tests only: seconds every chunk write of the recorder sleeps first (a slow disk)."""


@dataclass(frozen=True)
class RecorderConfig:
    """Where to record and when the run is complete."""

    bag_path: str = param('rosbag2 bag directory to create (it must not exist)')
    expected_steps: int = param('the run is complete after this many steps (0: record until '
                                'stopped)', low=0, default=0, high=10_000_000)
    flush_period_s: float = param('wall mode: a chunk is written at least this often',
                                  unit='s', low=0.0, low_inclusive=False, default=1.0, high=3600.0)
    max_chunks_per_file: int = param('chunks (steps) per MCAP file before the recording goes on '
                                     'in the next (rosbag2 split; bounds the memory of a long '
                                     'recording)', low=1, default=MAX_CHUNKS_PER_FILE,
                                     high=10_000_000)
    record_file: str = param("YAML mapping of the run's record (what ran, the effective "
                             "parameters) for the bag's custom_data ('' = none)", default='')

    def __post_init__(self) -> None:
        check_fields(self)


def read_record(path: str) -> dict[str, str]:
    """The run's record the orchestrator wrote (:mod:`trust_av.system.run_record`):
    ``custom_data`` entries, strings to strings ({} for no file).

    Raises:
        TrustAvAppError: the file cannot be read or is not such a mapping.
    """
    if not path:
        return {}
    try:
        document = yaml.safe_load(Path(path).read_text())
    except (OSError, yaml.YAMLError) as err:
        raise TrustAvAppError(f'record_file {path}: cannot read it ({err})') from err
    if not (isinstance(document, dict)
            and all(isinstance(k, str) and isinstance(v, str) for k, v in document.items())):
        raise TrustAvAppError(f'record_file {path}: not a mapping of text to text')
    return document


class RecorderNode(Node):
    """Raw subscriptions to every recorded topic of the table; one bag directory."""

    def __init__(self) -> None:
        super().__init__('recorder')
        self.finished = False
        self.stopping = False  # set by spin_node on a stop request
        self.exit_code = 0
        self.config = declare_config(self, RecorderConfig)
        self.clock = declare_config(self, WallClockConfig)
        self.bag = BagWriter(Path(self.config.bag_path),
                             custom_data=read_record(self.config.record_file),
                             max_chunks_per_file=self.config.max_chunks_per_file)
        self.write_delay_s = float(os.environ.get(WRITE_DELAY_ENV, '0') or 0)
        self.needed: dict[str, int] = {}
        self.publishers_needed: dict[str, int] = {}
        self.subscriptions_by_topic = {}
        self.incomplete = 0
        steps = self.config.expected_steps
        for topic in TOPICS:
            if 'recorder' not in topic.subscribers:
                continue
            name = self.resolve_topic_name(topic.name)  # the bag holds full names
            self.bag.add_topic(name, topic.msgtype,
                               offered_profiles(QOS[topic.qos], len(topic.publishers)))
            self.publishers_needed[name] = len(topic.publishers)
            if steps:
                self.needed[name] = topic.messages(steps)
                self.incomplete += 1
            self.subscriptions_by_topic[name] = self.create_subscription(
                message_class(topic.msgtype), topic.name,
                functools.partial(self.on_message, name), QOS[topic.qos], raw=True)
        self.gap_topics = {self.resolve_topic_name(name)
                           for name in ('ego/planner_status', 'human/driver_status')}
        self.step_topic = self.resolve_topic_name(
            next(t.name for t in TOPICS if t.msgtype == 'rosgraph_msgs/msg/Clock'))
        self.pub_status = self.create_publisher(DiagnosticArray, STATUS_TOPIC, QOS['LATCHED'])
        # back-pressure (lock-step): complete steps held per topic, acknowledged to the
        # step authority
        self.ack_rows = {self.resolve_topic_name(t.name): (t.per_step, t.initial)
                         for t in recorded_topics()}
        self.held = dict.fromkeys(self.ack_rows, 0)
        self.acked = 0
        self.pub_ack = (None if self.clock.wall else
                        self.create_publisher(UInt64, ACK_TOPIC, QOS['LATCHED']))
        self.ready = False
        self.last_status_s = 0.0
        self.ready_timer = self.create_timer(READY_CHECK_PERIOD_S, self.check_ready)
        self.flush_timer = (self.create_timer(self.config.flush_period_s, self.flush)
                            if self.clock.wall else None)
        self.get_logger().info(f'recording {len(self.subscriptions_by_topic)} topics to '
                               f'{self.bag.path}; waiting for their publishers')

    def check_ready(self) -> None:
        """Say ``ready`` once every subscription has matched its publishers."""
        missing = [name for name, sub in self.subscriptions_by_topic.items()
                   if sub.get_publisher_count() < self.publishers_needed[name]]
        if missing or self.ready:
            return
        self.ready = True
        self.ready_timer.cancel()
        self.publish_status('ready')
        self.get_logger().info('ready: every recorded topic has its publishers')

    def publish_status(self, state: str) -> None:
        """``recorder/status``: the state, the steps and the messages written so far."""
        self.last_status_s = time.monotonic()
        self.pub_status.publish(diagnostics(
            0, 'recorder', self.exit_code == 0, state,
            {'state': state, 'steps': str(self.bag.steps),
             'messages': str(sum(self.bag.counts.values())), 'bag': str(self.bag.path)}))

    def on_message(self, topic: str, data: bytes) -> None:
        """Write one raw message; a ``clock`` tick closes the step before it."""
        if self.finished:
            return
        if topic == self.step_topic and not self.end_step():
            self.stop_disk_full()
            return
        # wall mode, as ros2 bag record: log time = receive time (publish time = the stamp)
        self.bag.write(topic, data, receive_time_ns=time.time_ns() if self.clock.wall else None)
        row = self.ack_rows.get(topic)
        if row is not None and self.pub_ack is not None:
            self.acknowledge(topic, row)
        if topic in self.gap_topics and self.needed and self.collided(topic, data):
            if self.incomplete == 0:
                self.complete()
            return
        needed = self.needed.get(topic)
        if needed is not None and self.bag.count(topic) == needed:
            self.incomplete -= 1
            if self.incomplete == 0:
                self.complete()
                return
        if time.monotonic() - self.last_status_s >= STATUS_PERIOD_S and self.ready:
            self.publish_status('recording')

    def collided(self, topic: str, data: bytes) -> bool:
        """Lock-step: a step status (``data`` on ``topic``) whose gap is at or below 0 m
        makes that step the run's last (the step authority starts no other): the run is
        complete with every message of the steps up to it (``needed`` and ``incomplete``
        recounted). True if it is a collision."""
        gap = status_gap_m(deserialize_message(data, DiagnosticArray))
        if gap is None or gap > 0.0:
            return False
        steps = self.bag.count(topic)         # this status is the step's: one per step
        for row in TOPICS:
            name = self.resolve_topic_name(row.name)
            if name in self.needed:
                self.needed[name] = min(self.needed[name], row.messages(steps))
        self.incomplete = sum(1 for name, needed in self.needed.items()
                              if self.bag.count(name) < needed)
        return True

    def acknowledge(self, topic: str, row: tuple[int, int]) -> None:
        """Count one message of a recorded per-step topic; acknowledge the complete steps
        held on every topic once they have grown by ``ACK_EVERY_STEPS``."""
        per_step, initial = row
        held = (self.bag.count(topic) - initial) // per_step
        if held <= self.held[topic]:
            return
        self.held[topic] = held
        steps = min(self.held.values())
        if steps >= self.acked + ACK_EVERY_STEPS:
            self.acked = steps
            self.pub_ack.publish(UInt64(data=steps))  # type: ignore[union-attr]

    def flush(self) -> None:
        """Wall mode: write what arrived since the last chunk."""
        if not self.finished and not self.end_step():
            self.stop_disk_full()

    def end_step(self) -> bool:
        """Write the step's chunk (after the test-only delay of a slow disk); False once
        the disk is full."""
        if self.write_delay_s:
            time.sleep(self.write_delay_s)
        return self.bag.end_step()

    def complete(self) -> None:
        """Every message of every expected step is in: finish the bag and end."""
        self.bag.finish()
        if self.bag.disk_full:
            self.stop_disk_full()
            return
        self.get_logger().info(f'recorded {sum(self.bag.counts.values())} messages '
                               f'({self.bag.steps} chunks) to {self.bag.path}')
        self.publish_status('finished')
        self.finished = True

    def stop_disk_full(self) -> None:
        """The disk is full: the bag was finished with the complete steps; end with code 3."""
        self.exit_code = EXIT_DISK_FULL
        print(f'error: {self.bag.disk_full}', file=sys.stderr, flush=True)
        self.publish_status('disk_full')
        self.finished = True

    def close(self) -> None:
        """Finish the bag (also on a stop request, with what arrived until then)."""
        self.bag.finish()
        if self.bag.disk_full and self.exit_code == 0:
            self.exit_code = EXIT_DISK_FULL
            print(f'error: {self.bag.disk_full}', file=sys.stderr, flush=True)


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ros2 run trust_av_planner recorder``."""
    return spin_node(RecorderNode, args)


if __name__ == '__main__':
    sys.exit(main())
