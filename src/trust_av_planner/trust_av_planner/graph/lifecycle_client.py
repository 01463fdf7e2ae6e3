"""Driving managed nodes from an orchestrator, as ``ros2 lifecycle set`` does:
``lifecycle_msgs/srv/GetState`` on ``/<node>/get_state`` and ``ChangeState`` on
``/<node>/change_state``.

The services, their names and their answers are rclpy's and rcl_lifecycle's: rclpy's
``LifecycleNodeMixin`` (``rclpy/lifecycle/node.py``) serves them under the names
rcl_lifecycle gives them (``~/get_state``, ``~/change_state``,
``rcl_lifecycle/src/com_interface.c``); ``ChangeState`` answers ``success`` True only when
the transition's callback returned SUCCESS. States and transitions are given by id
(``lifecycle_msgs/msg/State``: unconfigured 1, inactive 2, active 3;
``lifecycle_msgs/msg/Transition``: configure 1, activate 3, deactivate 4), and the path to
a state follows rcl_lifecycle's default state machine
(``rcl_lifecycle/src/default_state_machine.c``): unconfigured -configure-> inactive
-activate-> active -deactivate-> inactive.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Iterator, Sequence
from typing import Any

from trust_av_planner.graph import stop_signals
from trust_av_planner.graph.processes import Graph, GraphError

UNCONFIGURED, INACTIVE, ACTIVE = 1, 2, 3
CONFIGURE, ACTIVATE, DEACTIVATE = 1, 3, 4
PATHS = {(UNCONFIGURED, INACTIVE): (CONFIGURE,), (UNCONFIGURED, ACTIVE): (CONFIGURE, ACTIVATE),
         (INACTIVE, ACTIVE): (ACTIVATE,), (ACTIVE, INACTIVE): (DEACTIVATE,)}
"""(state, goal) -> the transitions that lead there."""
LABELS = {CONFIGURE: 'configure', ACTIVATE: 'activate', DEACTIVATE: 'deactivate'}
GOALS = {'inactive': INACTIVE, 'active': ACTIVE}


def set_states(node: Any, executor: Any, names: Sequence[str], goal: str,
               timeout_s: float = 30.0, graph: Graph | None = None) -> None:
    """Bring each node of ``names`` to ``goal`` (``inactive`` or ``active``) from whatever
    state it is in (one that configured itself is not configured again), spinning
    ``executor`` (which holds ``node``) meanwhile.

    Args:
        node: this process's node, the services' client.
        executor: the executor spinning ``node``.
        names: the managed nodes' names (root namespace).
        goal: ``inactive`` or ``active``.
        timeout_s: longest wait for a node's services and for each answer, s.
        graph: the running graph, if any: a node of it that dies meanwhile is named.

    Raises:
        GraphError: a node's service did not appear or answer in time, a transition
            failed (the node's log says why) or the node is in a state with no path to
            ``goal`` (finalized).
    """
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState, GetState

    def alive() -> None:
        if graph is not None:
            graph.check_alive(set())

    def call(client: Any, request: Any, what: str) -> Any:
        _wait(executor, timeout_s, client.service_is_ready, f'{what}: no service', alive)
        future = client.call_async(request)
        _wait(executor, timeout_s, future.done, f'{what}: no answer', alive)
        return future.result()

    for name in names:
        get = node.create_client(GetState, f'/{name}/get_state')
        change = node.create_client(ChangeState, f'/{name}/change_state')
        try:
            state = int(call(get, GetState.Request(), f'node {name}').current_state.id)
            if state == GOALS[goal]:
                continue
            if (state, GOALS[goal]) not in PATHS:
                raise GraphError(f'node {name}: lifecycle state {state} has no path to {goal}')
            for transition in PATHS[state, GOALS[goal]]:
                request = ChangeState.Request(transition=Transition(id=transition))
                label = LABELS[transition]
                if not call(change, request, f'node {name}: {label}').success:
                    raise GraphError(f'node {name}: transition {label} failed (see its log)')
        finally:
            node.destroy_client(get)
            node.destroy_client(change)


@contextlib.contextmanager
def lifecycle_manager(domain: int) -> Iterator[tuple[Any, Any]]:
    """A node and its executor on a private rclpy context in ``domain``, for a process that
    starts nodes without being a ROS node itself (benchmarks, tests)."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node('lifecycle_manager', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        yield node, executor
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def _wait(executor: Any, timeout_s: float, done: Callable[[], bool], what: str,
          alive: Callable[[], None]) -> None:
    deadline = time.monotonic() + timeout_s
    while not done():
        if time.monotonic() > deadline:
            raise GraphError(f'{what} after {timeout_s:g} s')
        stop_signals.spin_once(executor, 0.02)
        alive()
