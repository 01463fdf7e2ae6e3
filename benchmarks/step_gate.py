"""One node's inputs counted per step, as the lock-step chain says them
(:func:`trust_av_common.step_chain.step_chain`): which steps the node may act on, in
order. The floor benchmark's nodes wait with it (``bench_floor.py``); the graph's own nodes
wait in their own code, so it lives here, with its one user."""

from __future__ import annotations

from trust_av_common.step_chain import NodeChain


class StepGate:
    """One node's inputs counted per step: which steps it may act on, in order.

    Args:
        node: the node's chain.
        t0_ns: stamp of step 0, ns.
        dt_ns: step, ns.
    """

    def __init__(self, node: NodeChain, t0_ns: int, dt_ns: int) -> None:
        self.offset = {p.topic: p.offset for p in node.inputs}
        self.node = node
        self.t0_ns = t0_ns
        self.dt_ns = dt_ns
        self.next = 0
        self._counts: dict[int, int] = {}

    def put(self, topic: str, stamp_ns: int) -> list[int]:
        """Count one message; the steps (oldest first) whose inputs are now complete.

        A message for a step before the next one (the initial state, to the source) is
        ignored.
        """
        step = (stamp_ns - self.t0_ns + self.dt_ns // 2) // self.dt_ns - self.offset[topic]
        if step < self.next:
            return []
        self._counts[step] = self._counts.get(step, 0) + 1
        ready = []
        while 0 < self.node.needed(self.next) == self._counts.get(self.next, 0):
            del self._counts[self.next]
            ready.append(self.next)
            self.next += 1
        return ready
