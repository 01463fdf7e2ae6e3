"""Driving managed nodes from an orchestrator: ``lifecycle_msgs/srv/ChangeState`` on
``/<node>/change_state``, as ``ros2 lifecycle set`` does.

The service, its name and its request are rclpy's and rcl_lifecycle's: rclpy's
``LifecycleNodeMixin`` (``rclpy/lifecycle/node.py``) serves ``ChangeState`` under the name
rcl_lifecycle gives it (``~/change_state``, ``rcl_lifecycle/src/com_interface.c``) and
answers ``success`` True only when the transition's callback returned SUCCESS; a transition
that is not valid from the current state is refused (``success`` False). Transitions are
given by id (``lifecycle_msgs/msg/Transition``: configure 1, cleanup 2, activate 3,
deactivate 4).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

from trust_av_planner.graph import stop_signals
from trust_av_planner.graph.processes import Graph, GraphError

TRANSITION_IDS = {'configure': 1, 'cleanup': 2, 'activate': 3, 'deactivate': 4}
"""``lifecycle_msgs/msg/Transition`` ids of the transitions an orchestrator requests."""


def change_states(graph: Graph, node: Any, executor: Any, names: Sequence[str],
                  transitions: Sequence[str], timeout_s: float = 30.0) -> None:
    """Run ``transitions`` in order on each node of ``names`` (each node's whole sequence,
    then the next node's), spinning ``executor`` (which holds ``node``) meanwhile.

    Args:
        graph: the running graph (a node that dies meanwhile is named).
        node: this process's node, the services' client.
        executor: the executor spinning ``node``.
        names: the managed nodes' names (root namespace).
        transitions: labels of :data:`TRANSITION_IDS`.
        timeout_s: longest wait for a node's service and for each answer, s.

    Raises:
        GraphError: a node's service did not appear or answer in time, a transition
            failed (the node's log says why), or a node died.
    """
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState

    for name in names:
        client = node.create_client(ChangeState, f'/{name}/change_state')
        try:
            _wait(graph, executor, timeout_s, client.service_is_ready,
                  f'{name}: no lifecycle service /{name}/change_state')
            for label in transitions:
                request = ChangeState.Request(transition=Transition(id=TRANSITION_IDS[label]))
                future = client.call_async(request)
                _wait(graph, executor, timeout_s, future.done,
                      f'{name}: transition {label} not answered')
                if not future.result().success:
                    raise GraphError(f'node {name}: transition {label} failed (see its log)')
        finally:
            node.destroy_client(client)


def _wait(graph: Graph, executor: Any, timeout_s: float, done: Any, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while not done():
        if time.monotonic() > deadline:
            raise GraphError(f'{what} after {timeout_s:g} s')
        stop_signals.spin_once(executor, 0.02)
        graph.check_alive(set())
