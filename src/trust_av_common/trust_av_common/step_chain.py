"""The lock-step dependency chain, derived from the topic table (pure Python, no rclpy).

The topic table :data:`trust_av_common.topics.TOPICS` lists the topics and their stamps (the
protocol in words: the documentation's node-graph page); this module turns the table into
the chain a node follows: for every node, which messages (topic, stamp) it must hold before
it acts on step t, and the stamps of what it then publishes. A stalled graph run names the
node it waits for by the chain's order (:mod:`trust_av.graph.stalls`); the floor benchmark
(``benchmarks/bench_floor.py``, with its ``step_gate``) replays the graph from it, so the
replica follows the table.

Rules (each from the table, none from a second list):

- the **step source** is the publisher of ``/clock``; it acts first in a step, and its
  inputs tell it that step t is complete;
- a **state topic** is one whose rate says it also carries the initial state (the
  odometry): its publisher sends the state at t0 at start-up and, acting on step t, the
  state after the step, stamped t + dt. Another node uses the state stamped t at step t;
  the source waits for the one stamped t + dt;
- the other per-step topics are stamped t. Where they form a cycle between nodes (the
  planner's trust comes from the monitor that reads the planner's plans), the edge that
  goes back towards the source is a **previous-step** input: stamped t - 1, none at t = 0.
  Back means: the subscriber is nearer the source (breadth-first, over the non-state
  edges) than the publisher; a cycle with no such edge is ambiguous (error).

Offsets are in steps: a node acting on step t needs, for each input, the message stamped
t + offset (inputs with t + offset < 0 are not needed), and stamps each output t + offset.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass

from trust_av_common.errors import TrustAvError
from trust_av_common.topics import TOPICS, Topic

__all__ = ['RECORDER', 'Port', 'StepChain', 'StepChainError', 'step_chain']

CLOCK_TOPIC = 'clock'
INITIAL_STATE_MARK = '+ the initial state'
"""Text of a topic's ``rate`` that makes it a state topic (published at start-up too)."""
ORCHESTRATOR = 'orchestrator'
RECORDER = 'recorder'


class StepChainError(TrustAvError):
    """The topic table does not define one lock-step chain (the message says why)."""


@dataclass(frozen=True)
class Port:
    """One input or output of a node: the topic and the stamp offset in steps."""

    topic: str
    offset: int


@dataclass(frozen=True)
class NodeChain:
    """What one node waits for and what it publishes, per step.

    Attributes:
        name: node name.
        inputs: messages needed to act on step t (stamp t + offset; omitted if < 0).
        outputs: messages published when acting on step t (stamp t + offset).
        initial: state topics published once at start-up, stamped t0.
        start: topics that start the node (the orchestrator's go signal; source only).
    """

    name: str
    inputs: tuple[Port, ...]
    outputs: tuple[Port, ...]
    initial: tuple[str, ...]
    start: tuple[str, ...]

    def needed(self, step: int) -> int:
        """Number of inputs the node needs for ``step`` (fewer at the first steps)."""
        return sum(1 for p in self.inputs if step + p.offset >= 0)


@dataclass(frozen=True)
class StepChain:
    """The whole chain: the source, the nodes in the order they act within a step."""

    source: str
    nodes: tuple[NodeChain, ...]
    state_topics: tuple[str, ...]

    def node(self, name: str) -> NodeChain:
        """The chain of one node.

        Raises:
            KeyError: no such node.
        """
        for node in self.nodes:
            if node.name == name:
                return node
        raise KeyError(name)


def step_chain(topics: Iterable[Topic] = TOPICS) -> StepChain:
    """Derive the lock-step chain from a topic table (see the module docstring).

    Raises:
        StepChainError: no ``/clock`` publisher, a node the source does not reach, a
            cycle that no stamp offset breaks, or a source without a start signal.
    """
    table = tuple(topics)
    clock = [t for t in table if t.name == CLOCK_TOPIC]
    if len(clock) != 1:
        raise StepChainError(f'expected one {CLOCK_TOPIC} topic, found {len(clock)}')
    source = clock[0].publishers[0]
    state = {t.name for t in table if INITIAL_STATE_MARK in t.rate}
    names = {p for t in table for p in t.publishers} | {s for t in table for s in t.subscribers}
    names -= {ORCHESTRATOR, RECORDER}
    step = [t for t in table if ORCHESTRATOR not in t.publishers]
    back, forward = _split_edges(source, names, step, state)
    chains = [_node_chain(node, source, table, step, state, back)
              for node in _topological(names, forward)]
    if not chains[0].start:
        raise StepChainError(f'the step source {source} subscribes no {ORCHESTRATOR} topic')
    return StepChain(source=source, nodes=tuple(chains),
                     state_topics=tuple(t.name for t in table if t.name in state))


def _split_edges(source: str, names: set[str], step: list[Topic], state: set[str],
                 ) -> tuple[set[tuple[str, str]], set[tuple[str, str]]]:
    """The same-step edges between nodes (not into the source, not state), split into the
    previous-step ones, as (publisher, topic), and the forward ones, as (publisher,
    subscriber).

    Raises:
        StepChainError: a node the source does not reach.
    """
    edges = {(p, s, t.name) for t in step for p in t.publishers for s in t.subscribers
             if s in names and s != source and t.name not in state}
    pairs = {(a, b) for a, b, _ in edges}
    level = _levels(source, pairs)
    unreached = sorted(names - set(level))
    if unreached:
        raise StepChainError(f'nodes not reached from the step source {source}: '
                             f'{", ".join(unreached)}')
    back = {(a, name) for a, b, name in edges if level[b] < level[a] and _reaches(b, a, pairs)}
    forward = {(a, b) for a, b, name in edges if (a, name) not in back}
    return back, forward


def _node_chain(node: str, source: str, table: tuple[Topic, ...], step: list[Topic],
                state: set[str], back: set[tuple[str, str]]) -> NodeChain:
    """One node's inputs (stamp offsets), outputs, initial states and start topics."""
    inputs = tuple(Port(t.name, _input_offset(node, source, t, state, back))
                   for t in step if node in t.subscribers)
    outputs = tuple(Port(t.name, 1 if t.name in state else 0)
                    for t in step if node in t.publishers)
    return NodeChain(
        name=node, inputs=inputs, outputs=outputs,
        initial=tuple(t.name for t in step if node in t.publishers and t.name in state),
        start=tuple(t.name for t in table if ORCHESTRATOR in t.publishers
                    and node in t.subscribers))


def _input_offset(node: str, source: str, topic: Topic, state: set[str],
                  back: set[tuple[str, str]]) -> int:
    """The stamp offset, in steps, of ``topic`` as an input of ``node``: the source waits
    for the state after the step (+1), a previous-step input is one step old (-1)."""
    if node == source:
        return 1 if topic.name in state else 0
    return -1 if any((p, topic.name) in back for p in topic.publishers) else 0


def _levels(source: str, edges: set[tuple[str, str]]) -> dict[str, int]:
    """Breadth-first distance of every node from ``source``."""
    level = {source: 0}
    queue = deque([source])
    while queue:
        a = queue.popleft()
        for x, b in sorted(edges):
            if x == a and b not in level:
                level[b] = level[a] + 1
                queue.append(b)
    return level


def _reaches(start: str, goal: str, edges: set[tuple[str, str]]) -> bool:
    """True when ``goal`` is reachable from ``start``."""
    seen, todo = {start}, [start]
    while todo:
        a = todo.pop()
        if a == goal:
            return True
        for x, b in edges:
            if x == a and b not in seen:
                seen.add(b)
                todo.append(b)
    return False


def _topological(nodes: set[str], edges: set[tuple[str, str]]) -> list[str]:
    """Nodes in an order where every edge goes forward (ties by name).

    Raises:
        StepChainError: a cycle is left.
    """
    indegree = {n: sum(1 for _, b in edges if b == n) for n in nodes}
    order: list[str] = []
    ready = sorted(n for n, d in indegree.items() if d == 0)
    while ready:
        a = ready.pop(0)
        order.append(a)
        for x, b in sorted(edges):
            if x == a:
                indegree[b] -= 1
                if indegree[b] == 0:
                    ready.append(b)
                    ready.sort()
    if len(order) != len(nodes):
        raise StepChainError('cycle within one step that no stamp offset breaks (no edge of '
                             'it goes back towards the source): '
                             + ', '.join(sorted(nodes - set(order))))
    return order
