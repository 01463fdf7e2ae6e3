"""Back-pressure from the recorder to the step authority (pure Python, no rclpy): how far
the lock-step graph may run ahead of what the recorder holds, so that no recorded message
is ever dropped.

A reliable DDS topic still drops samples when a history overflows: the recorder's
subscription and every publisher keep the last :data:`HISTORY_DEPTH` samples of a topic
(``KEEP_LAST``), and a recorder that is suspended or slow (SIGSTOP, a slow disk, a busy
host) stops taking them while the graph goes on. So the recorder acknowledges the steps it
holds (the smallest, over the recorded topics, of ``(count - initial) // per_step``,
published on ``recorder/ack`` every :data:`ACK_EVERY_STEPS` steps) and the step authority
starts step ``s`` only when ``s < acked + window`` (:func:`window_steps`).

Why nothing is lost (per recorded topic, ``per`` messages a step, ``initial`` before the
first one): when step ``s`` starts, at most ``per * (s + 1) + initial`` messages of the
topic have been published and the recorder has taken ``count >= per * held + initial``,
with ``held >= acked > s - window``. So at most ``per * window`` of them are anywhere
between the publishers and the recorder (a publisher's history, the wire, the recorder's
history): with ``per * window <= HISTORY_DEPTH / 2`` no history can overflow, whatever the
order in which the messages of several publishers arrive (the bound counts messages, not
complete steps) and however long the recorder stands still.
"""

from __future__ import annotations

from collections.abc import Iterable

from trust_av_common.topics import TOPICS, Topic

__all__ = ['ACK_EVERY_STEPS', 'ACK_TOPIC', 'HISTORY_DEPTH', 'may_start',
           'recorded_topics', 'window_steps']

HISTORY_DEPTH = 1000
"""Samples kept per topic by every lock-step publisher and subscription (``KEEP_LAST``)."""
ACK_EVERY_STEPS = 8
"""The recorder acknowledges its progress at most once per this many steps."""
RECORDER = 'recorder'
ACK_TOPIC = 'recorder/ack'
"""The recorder's acknowledgement: ``std_msgs/UInt64``, the number of complete steps it
holds (latched: the newest only)."""


def recorded_topics(topics: Iterable[Topic] = TOPICS) -> tuple[Topic, ...]:
    """The per-step topics the recorder records.

    Args:
        topics: the topic table.
    """
    return tuple(t for t in topics if RECORDER in t.subscribers and t.per_step > 0)


def window_steps(depth: int = HISTORY_DEPTH, topics: Iterable[Topic] = TOPICS) -> int:
    """Steps the graph may run ahead of the recorder's acknowledgement: the largest window
    that keeps every recorded topic's messages in flight within half of ``depth``.

    Args:
        depth: samples kept per topic by the publishers and the recorder.
        topics: the topic table.

    Raises:
        ValueError: the window would not exceed :data:`ACK_EVERY_STEPS` (the graph could
            wait for an acknowledgement the recorder never sends).
    """
    per_step = max(t.per_step for t in recorded_topics(topics))
    window = depth // (2 * per_step)
    if window <= ACK_EVERY_STEPS:
        raise ValueError(f'history depth {depth} leaves a recorder window of {window} steps, '
                         f'not more than the acknowledgement period {ACK_EVERY_STEPS}')
    return window


def may_start(step: int, acked: int, window: int) -> bool:
    """Whether the step authority may start a step.

    Args:
        step: the step to start (0-based).
        acked: complete steps the recorder has acknowledged.
        window: steps the graph may run ahead of ``acked`` (0: no recorder to wait for).
    """
    return window == 0 or step < acked + window
