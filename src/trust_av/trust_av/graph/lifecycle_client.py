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

import time
from collections.abc import Callable, Sequence
from typing import Any

from trust_av.graph import stop_signals
from trust_av.graph.processes import Graph, GraphError

__all__ = ['MANAGED_NODES', 'set_states']

MANAGED_NODES = ('planner', 'trust_monitor')
"""The project's managed (lifecycle) nodes: what an orchestrator configures and activates."""
UNCONFIGURED, INACTIVE, ACTIVE = 1, 2, 3
CONFIGURE, ACTIVATE, DEACTIVATE = 1, 3, 4
PATHS = {(UNCONFIGURED, INACTIVE): (CONFIGURE,), (UNCONFIGURED, ACTIVE): (CONFIGURE, ACTIVATE),
         (INACTIVE, ACTIVE): (ACTIVATE,), (ACTIVE, INACTIVE): (DEACTIVATE,)}
"""(state, goal) -> the transitions that lead there."""
LABELS = {CONFIGURE: 'configure', ACTIVATE: 'activate', DEACTIVATE: 'deactivate'}
GOALS = {'inactive': INACTIVE, 'active': ACTIVE}


ANSWER_S = 2.0
"""How long an answer is waited for before the state is asked again (a lost answer)."""
ATTEMPTS = 3
"""Times one transition is sent from one state before it counts as failed."""
TRANSITIONING = range(10, 16)
"""``lifecycle_msgs/msg/State`` ids of the transition states (configuring ... errorprocessing)."""


def set_states(node: Any, executor: Any, names: Sequence[str], goal: str,
               timeout_s: float = 30.0, graph: Graph | None = None) -> None:
    """Bring each node of ``names`` to ``goal`` (``inactive`` or ``active``) from whatever
    state it is in (one that configured itself is not configured again), spinning
    ``executor`` (which holds ``node``) meanwhile.

    A service client is "ready" once the server takes its requests, which is not proof that
    the answer finds its way back: a client made just before (the server's answer writer not
    yet matched with the client's reader, under load) waited forever for an answer that was
    sent and lost (seen in a full test run: ``no answer after 30 s``). So an answer is
    waited for :data:`ANSWER_S`, then the state is asked again (``GetState`` is asked until
    it answers), and the next transition is chosen from the state the node reports: a
    transition whose answer was lost is not sent twice, one whose request was lost is.

    Args:
        node: this process's node, the services' client.
        executor: the executor spinning ``node``.
        names: the managed nodes' names, namespace included, without the leading slash.
        goal: ``inactive`` or ``active``.
        timeout_s: longest time for each node to reach ``goal``, s.
        graph: the running graph, if any: a node of it that dies meanwhile is named.

    Raises:
        GraphError: a node's services did not appear or answer in time, a transition
            failed (the node's log says why) or the node is in a state with no path to
            ``goal`` (finalized).
    """
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState, GetState

    def alive() -> None:
        if graph is not None:
            graph.check_alive(set())

    for name in names:
        get = node.create_client(GetState, f'/{name}/get_state')
        change = node.create_client(ChangeState, f'/{name}/change_state')
        deadline = time.monotonic() + timeout_s
        sent: dict[tuple[int, int], int] = {}
        try:
            for client in (get, change):
                _wait(executor, deadline, client.service_is_ready,
                      f'node {name}: no lifecycle services after {timeout_s:g} s', alive)
            while True:
                state = _ask(executor, get, GetState.Request(), deadline, f'node {name}',
                             alive).current_state.id
                if state == GOALS[goal]:
                    break
                if state in TRANSITIONING:
                    continue                # its executor was busy with it: ask again
                if (state, GOALS[goal]) not in PATHS:
                    raise GraphError(f'node {name}: lifecycle state {state} has no path to '
                                     f'{goal}')
                transition = PATHS[state, GOALS[goal]][0]
                label = LABELS[transition]
                sent[state, transition] = sent.get((state, transition), 0) + 1
                if sent[state, transition] > ATTEMPTS:
                    raise GraphError(f'node {name}: transition {label} failed{_why(graph, name)}')
                future = change.call_async(
                    ChangeState.Request(transition=Transition(id=transition)))
                if not _answered(executor, future, min(deadline, time.monotonic() + ANSWER_S),
                                 alive):
                    change.remove_pending_request(future)   # the state, asked next, tells
                elif not future.result().success:
                    raise GraphError(f'node {name}: transition {label} failed{_why(graph, name)}')
        finally:
            node.destroy_client(get)
            node.destroy_client(change)


def _why(graph: Any, name: str) -> str:
    """``': WHY'`` from the node's log (the one line a managed node logs for a refused
    ``configure``: ``configure failed: WHY``), else ``' (see its log)'``."""
    marker = 'configure failed: '
    try:
        log = graph.by_name(name.rsplit('/', 1)[-1]).log_path.read_text(errors='replace')
    except (AttributeError, StopIteration, OSError):
        return ' (see its log)'
    lines = [line for line in log.splitlines() if marker in line]
    last = lines[-1].split(marker, 1)[1].strip() if lines else ''
    return f': {last}' if last and last != 'Traceback (most recent call last):' \
        else ' (see its log)'


def _ask(executor: Any, client: Any, request: Any, deadline: float, what: str,
         alive: Callable[[], None]) -> Any:
    """``request``'s answer, asked again every :data:`ANSWER_S` until ``deadline`` (for a
    request that may be asked twice, such as GetState); an unanswered request is withdrawn
    from the client before the next, so that a late answer completes nothing and no
    request is left pending."""
    while True:
        future = client.call_async(request)
        if _answered(executor, future, min(deadline, time.monotonic() + ANSWER_S), alive):
            return future.result()
        client.remove_pending_request(future)
        if time.monotonic() >= deadline:
            raise GraphError(f'{what}: no answer in time')


def _answered(executor: Any, future: Any, until: float, alive: Callable[[], None]) -> bool:
    """Spin until ``future`` is done (True) or ``until`` (monotonic s) passes (False)."""
    while not future.done():
        if time.monotonic() >= until:
            return False
        stop_signals.spin_once(executor, 0.02)
        alive()
    return True


def _wait(executor: Any, deadline: float, done: Callable[[], bool], what: str,
          alive: Callable[[], None]) -> None:
    while not done():
        if time.monotonic() > deadline:
            raise GraphError(what)
        stop_signals.spin_once(executor, 0.02)
        alive()
