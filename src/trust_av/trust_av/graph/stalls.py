"""Which node a stalled lock-step run waits for.

A run stalls when the recorder records no step for the stall timeout. The node to blame is
told apart three ways, in this order:

- **stopped**: its state in ``/proc/PID/stat`` is ``T`` or ``t`` (SIGSTOP, Ctrl-Z of the
  node, a debugger). Such a node makes no progress however long it is stopped, so the time
  counts towards the stall like any other;
- **busy**: it used more than :data:`BUSY_SHARE` of the stall's wall time on a CPU (a loop
  that never returns to its executor);
- **waiting**: otherwise (a deadlock, a lost message), the messages the recorder holds say
  it: each node's steps done are the counts of the topics it alone publishes, and the node
  the chain waits for is the first one, in the order the nodes act within a step
  (:func:`trust_av_common.step_chain.step_chain`), that has done fewer steps than the
  step source.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

from trust_av_common.step_chain import step_chain
from trust_av_common.topics import TOPICS, qualified

__all__ = ['BUSY_SHARE', 'cpu_s', 'steps_done', 'waited_for', 'waiting_for']

BUSY_SHARE = 0.5
"""A node that used more than this share of the stall's wall time on a CPU is busy."""

_TICKS_PER_S = os.sysconf('SC_CLK_TCK')


def cpu_s(pid: int) -> float:
    """CPU time (user + system) the process ``pid`` used so far, s (0.0 once it is gone)."""
    try:
        fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[-1].split()
    except OSError:
        return 0.0
    # after the command: state(0) ppid(1) ... utime(11) stime(12) (proc(5) fields 14, 15)
    return (int(fields[11]) + int(fields[12])) / _TICKS_PER_S


def steps_done(counts: Mapping[str, int], namespace: str = '/') -> dict[str, int]:
    """Steps each node has acted on, from the messages recorded per topic (full names).

    Only topics with one publisher count (``/tf``'s three publishers cannot be told apart
    by a count); a node's steps are the fewest over those of its outputs.
    """
    done: dict[str, int] = {}
    for row in TOPICS:
        name = qualified(row.name, namespace)
        if len(row.publishers) != 1 or row.per_step < 1 or name not in counts:
            continue
        steps = max(0, (counts[name] - row.initial) // row.per_step)
        node = row.publishers[0]
        done[node] = min(done.get(node, steps), steps)
    return done


def waiting_for(counts: Mapping[str, int], namespace: str = '/') -> str:
    """The node the chain waits for ('' if the counts do not tell: every node has done as
    many steps as the step source, which then waits for the recorder or for itself)."""
    chain = step_chain()
    done = steps_done(counts, namespace)
    source = done.get(chain.source)
    if source is None:
        return ''
    for node in chain.nodes:
        if node.name in done and done[node.name] < source:
            return node.name
    return ''


def waited_for(bag: Path, namespace: str) -> str:
    """``'; the chain waits for node NAME ...'`` from the finished bag's counts ('' if they
    do not tell or the bag does not read)."""
    from rosbags.rosbag2 import Reader, ReaderError

    try:
        with Reader(bag) as reader:
            counts = {c.topic: c.msgcount for c in reader.connections}
    except (ReaderError, OSError):
        return ''
    node = waiting_for(counts, namespace)
    return (f'; the chain waits for node {node} (it has every input of its next step and '
            'published nothing for it)' if node else '')
