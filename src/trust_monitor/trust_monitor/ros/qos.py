"""The graph's named QoS profiles: every publisher and subscription takes its profile from here
(by the name in :data:`trust_monitor.common.topics.TOPICS`), never a bare depth in node code.
"""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

HISTORY_DEPTH = 1000
"""Samples kept per topic on both sides. The recorder is not part of the lock-step, so it may
fall behind the graph while the machine is busy; a reader whose history overflows drops
samples even on a reliable topic (seen with depth 10 on a loaded machine: 6 steps lost)."""

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
