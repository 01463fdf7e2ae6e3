"""``/diagnostics``: every node's health as ``diagnostic_msgs/DiagnosticArray``, what ROS 2
tools read (``ros2 topic echo /diagnostics``, rqt_robot_monitor, diagnostic_aggregator,
Foxglove's diagnostics panels).

Published as ``diagnostic_updater`` publishes (``diagnostic_updater/diagnostic_updater.hpp``
of ros/diagnostics): on the absolute topic ``/diagnostics`` (one topic for the whole system,
also from a namespaced node: the status name carries the node's fully qualified name), once
per ``period`` = 1 s (its default ``diagnostic_updater.period``), reliable, volatile, keep last
1 (its publisher's QoS depth 1), and at once when a node's level or message changes (as
``Updater::force_update``), so a problem is on the topic within one control period. The timer
runs on the steady clock: a node whose ROS clock does not advance (``use_sim_time`` without
``/clock``) still reports that. Stamped with the node's clock, or the system clock while the
node's clock reads zero (sim time before the first ``/clock``).

The status of a node: ``level`` OK, WARN or ERROR (``DiagnosticStatus``), ``message`` one line
saying what it does or why it does not (``not commanding: ...``), ``values`` key/value pairs
(numbers with units in the key: ``solve_time_last_s``). What changes on every tick (an input's
age) goes in ``values``, never in ``message``: a changed message is published at once.

Named as ``diagnostic_updater`` names a status (``Updater``: ``node_name_ + ": " + name``,
``node_name_`` = the node's ``get_name()``, its fully qualified name only with its parameter
``diagnostic_updater.use_fqn``, default false): ``planner: trust_aware_nmpc`` in any namespace;
the node's fully qualified name is the value ``node``. ``hardware_id`` is ``none``, the value
the updater asks for when there is no device (an empty one makes it warn: "For devices that do
not have a HW_ID, set this value to 'none'").
"""

from __future__ import annotations

import time
from collections.abc import Callable

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from trust_av_common.health import ERROR, OK, WARN, Report, age
from trust_av_common.ros.messages import HARDWARE_ID, header
from trust_av_common.topics import NO_FRAME

__all__ = ['ERROR', 'OK', 'WARN', 'NodeDiagnostics', 'Report', 'age']

TOPIC = '/diagnostics'
PERIOD_S = 1.0
"""diagnostic_updater's default period (its parameter ``diagnostic_updater.period``)."""
QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                 reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
"""diagnostic_updater's publisher: ``create_publisher(..., "/diagnostics", 1)``."""


class NodeDiagnostics:
    """A node's ``/diagnostics`` publisher and its 1 Hz steady timer.

    Args:
        node: the node (its fully qualified name names the status).
        task: what the status is about (``trust_aware_nmpc``), after the node's name.
        report: returns the node's current (level, message, values).
    """

    def __init__(self, node: Node, task: str, report: Callable[[], Report]) -> None:
        self.node = node
        self.report = report
        self.name = f'{node.get_name()}: {task}'
        self.fqn = node.get_fully_qualified_name()
        self.publisher = node.create_publisher(DiagnosticArray, TOPIC, QOS)
        self.last: tuple[int, str] | None = None
        self.published = 0
        self.timer = node.create_timer(PERIOD_S, self.update,
                                       clock=Clock(clock_type=ClockType.STEADY_TIME))

    def stamp_ns(self) -> int:
        """The node's clock, or the system clock while the node's reads zero."""
        ns = int(self.node.get_clock().now().nanoseconds)
        return ns if ns > 0 else time.time_ns()

    def update(self) -> None:
        """Publish the node's status now."""
        level, message, values = self.report()
        status = DiagnosticStatus(level=level.to_bytes(1, 'little'), name=self.name,
                                  message=message, hardware_id=HARDWARE_ID)
        status.values = [KeyValue(key=k, value=v)
                         for k, v in {'node': self.fqn, **values}.items()]
        self.publisher.publish(DiagnosticArray(header=header(self.stamp_ns(), NO_FRAME),
                                               status=[status]))
        self.last = (level, message)
        self.published += 1

    def changed(self) -> None:
        """Publish at once if the level or the message differs from the last published
        (diagnostic_updater's ``force_update``); else wait for the timer."""
        level, message, _ = self.report()
        if (level, message) != self.last:
            self.update()
