"""The graph's named QoS profiles: every publisher and subscription takes its profile from here
(by the names in :data:`trust_av_common.topics.TOPICS`), never a bare depth in node code.

Lock-step (sim time) keeps what determinism needs: every per-step topic reliable, transient
local and deep (:data:`STEP_QOS`). Wall mode (real-vehicle mode) uses :func:`wall_qos`: the
vehicle's inputs as sensor data (best effort, volatile, keep last 1, no deadline unless
``input_deadline_qos``: they match every publisher, reliable or best effort, volatile or
transient local), the acceleration command reliable, volatile, keep last 1 with a
deadline of two control periods, everything else reliable and volatile. The reasons are in the
documentation's topic table (:func:`trust_av_common.topics.topic_table_markdown`).
"""

from __future__ import annotations

from rclpy.duration import Duration
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from trust_av_common.record_window import HISTORY_DEPTH as RECORD_HISTORY_DEPTH
from trust_av_common.topics import TOPIC
from trust_av_common.wall_clock import WallClockConfig

__all__ = ['QOS', 'RECORD_QOS', 'command_deadline_s', 'input_events', 'record_qos', 'topic_qos',
           'wall_qos']

HISTORY_DEPTH = RECORD_HISTORY_DEPTH
"""Samples kept per topic on both sides. A reader whose history overflows drops samples even
on a reliable topic (seen with depth 10 on a loaded machine: 6 steps lost); the recorder may
fall behind the graph, which therefore runs at most a window of steps ahead of it
(:mod:`trust_av_common.record_window`: the window keeps within half this depth)."""

STEP_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=HISTORY_DEPTH,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""Every per-step topic: nothing may be lost, and a late subscriber still gets the first
steps."""

CLOCK_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=HISTORY_DEPTH,
                       reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""/clock: reliable and transient local, so that a subscriber whose match with the traffic
node completes after the first tick still gets it (seen with 8 runs at once); rclpy's own
volatile time-source subscriber is compatible with it."""

LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""One-off signals (/sim/start) that a node started later must still receive."""

QOS = {'STEP': STEP_QOS, 'CLOCK': CLOCK_QOS, 'LATCHED': LATCHED_QOS}

STATE_DEPTH = 10
"""Wall mode, plans, status and trust: a few samples of slack for a reader that is briefly
late (the recorder), none for a late joiner (volatile)."""

RECORD_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=HISTORY_DEPTH,
                        reliability=ReliabilityPolicy.BEST_EFFORT,
                        durability=DurabilityPolicy.VOLATILE)
"""A wall-mode subscription compatible with every publisher (best effort, no deadline),
deep enough not to drop while its reader is busy."""


def record_qos(kind: str) -> QoSProfile:
    """A wall-mode recorder's subscription to a topic of wall-mode kind ``kind``
    (:func:`wall_qos`): as reliable as its publishers, like ``ros2 bag record``, so that a
    reliable publisher resends what a busy recorder missed and a stopping node waits for
    the recorder's acknowledgement (trust_av_common.ros.spin); best effort for sensor data,
    which cannot be asked for more. Volatile, keep last :data:`HISTORY_DEPTH`, no deadline
    (so it matches every publisher of the topic).

    Raises:
        KeyError: an unknown kind.
    """
    # The publishers' reliability, from the one definition of each kind (the rate and
    # timeout a clock sets do not change it).
    reliability = wall_qos(kind, WallClockConfig(), publisher=True).reliability
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=HISTORY_DEPTH,
                      reliability=reliability, durability=DurabilityPolicy.VOLATILE)


def command_deadline_s(clock: WallClockConfig) -> float:
    """Deadline of the acceleration command: two control periods, s."""
    return 2.0 / clock.control_rate_hz


def sensor_deadline_s(clock: WallClockConfig, publisher: bool) -> float:
    """Deadline of a vehicle input: requested ``input_timeout_s`` by a subscription, offered
    two control periods (at most ``input_timeout_s``) by a publisher, s."""
    requested = clock.input_timeout_s
    return min(command_deadline_s(clock), requested) if publisher else requested


def wall_qos(kind: str, clock: WallClockConfig, publisher: bool = False) -> QoSProfile:
    """The wall-mode profile of a topic kind (the ``wall_qos`` column of the topic table).

    The compatibility rules are rmw's (``rmw_qos_profile_check_compatible``, rmw
    ``qos_profiles.h``; implemented for the DDS middlewares in rmw_dds_common ``qos.cpp``):
    a best-effort subscription matches reliable and best-effort publishers, a volatile one
    volatile and transient-local publishers, and one that requests a deadline only
    publishers that offer one at least as short (a publisher without a deadline does not
    match). So vehicle inputs request no deadline by default and match the publishers of
    vehicle stacks (e.g. Autoware's kinematic state: reliable, volatile, keep last 1, no
    deadline); with ``input_deadline_qos`` they request ``input_timeout_s``, which this
    project's publishers offer (two control periods). The command is offered and requested
    with two control periods.

    Args:
        kind: ``SENSOR`` (vehicle inputs: best effort, volatile, keep last 1, a deadline
            only with ``input_deadline_qos``; publishers always offer one), ``COMMAND``
            (reliable, volatile, keep last 1, deadline two control periods), ``STATE``
            (reliable, volatile, keep last :data:`STATE_DEPTH`) or ``LATCHED``.
        clock: the node's wall-clock settings (rate, input timeout).
        publisher: the profile of a publisher (the offered deadline) rather than of a
            subscription (the requested one).

    Raises:
        KeyError: an unknown kind.
    """
    if kind == 'SENSOR':
        profile = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                             reliability=ReliabilityPolicy.BEST_EFFORT,
                             durability=DurabilityPolicy.VOLATILE)
        if publisher or clock.input_deadline_qos:
            profile.deadline = Duration(seconds=sensor_deadline_s(clock, publisher))
        return profile
    if kind == 'COMMAND':
        return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                          reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.VOLATILE,
                          deadline=Duration(seconds=command_deadline_s(clock)))
    if kind == 'STATE':
        return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=STATE_DEPTH,
                          reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.VOLATILE)
    if kind == 'LATCHED':
        return LATCHED_QOS
    raise KeyError(f'unknown wall-mode QoS kind {kind!r}')


def topic_qos(topic: str, clock: WallClockConfig, publisher: bool = False) -> QoSProfile:
    """The profile of a topic of the table in the node's clock mode: the lock-step profile
    (``qos`` column) or the wall-mode one (``wall_qos`` column, :func:`wall_qos`)."""
    row = TOPIC[topic]
    return wall_qos(row.wall_qos, clock, publisher) if clock.wall else QOS[row.qos]


def input_events(node: Node, name: str, missed: dict[str, int],
                 clock: WallClockConfig) -> SubscriptionEventCallbacks:
    """QoS events of a wall-mode input ``name``: a missed deadline is counted in
    ``missed[name]`` (the node treats the input as stale until its next message) and
    logged; an incompatible publisher (e.g. one without a deadline) is logged with the
    policy."""
    def on_deadline(info: object) -> None:
        missed[name] = missed.get(name, 0) + 1
        node.get_logger().warning(f'input {name}: QoS deadline missed (no message for '
                                  f'{clock.input_timeout_s:g} s)', throttle_duration_sec=1.0)

    def on_incompatible(info: object) -> None:
        policy = getattr(info, 'last_policy_kind', '?')
        need = ('a deadline <= input_timeout_s (or set input_deadline_qos false)'
                if clock.input_deadline_qos else 'a compatible profile')
        node.get_logger().error(f'input {name}: a publisher with incompatible QoS ({policy}) '
                                f'is not connected; vehicle inputs need {need}',
                                throttle_duration_sec=5.0)

    return SubscriptionEventCallbacks(deadline=on_deadline, incompatible_qos=on_incompatible)
