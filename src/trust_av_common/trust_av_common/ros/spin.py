"""A node's main loop (:func:`spin_node`: init, build, spin, shut down) and the wall-clock
control loop of real-vehicle mode (:class:`WallLoop`)."""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import time
from collections.abc import Callable, Iterable
from typing import Any, Protocol

import rclpy
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.duration import Duration
from rclpy.exceptions import InvalidParameterValueException, ParameterUninitializedException
from rclpy.executors import Executor, ExternalShutdownException
from rclpy.experimental.events_executor import EventsExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import ok, try_shutdown

from trust_av_common.component_checks import ComponentError
from trust_av_common.errors import one_line
from trust_av_common.params import ParamsError
from trust_av_common.registry import RegistryError
from trust_av_common.ros.diagnostics import OK, NodeDiagnostics
from trust_av_common.ros.parameters import check_overrides, use_command_line
from trust_av_common.wall_clock import NS_PER_S, LoopStats, WallClockConfig, format_summary

__all__ = ['PARENT_ENV', 'GraphNode', 'WallLoop', 'now_ns', 'spin_node', 'start_node',
           'wait_acked']


class WallLoop:
    """A node's wall-clock control loop: a timer at ``control_rate_hz`` whose every tick is
    timed (:class:`trust_av_common.wall_clock.LoopStats`); p50/p99 are logged every
    ``jitter_log_period_s`` and written to ``jitter_report_path`` by :meth:`close`, with the
    number of messages the node published per topic from then on (every publisher the node
    has when the loop is made is counted: its ``publish`` is wrapped)."""

    def __init__(self, node: Node, config: WallClockConfig, step: Callable[[], None]) -> None:
        self.node = node
        self.config = config
        self.step = step
        self.stats = LoopStats(config.period_ns)
        for publisher in node.publishers:
            self._count(publisher)
        self._next_log_ns = time.monotonic_ns() + round(config.jitter_log_period_s * NS_PER_S)
        # the steady clock: wall mode never waits on a ROS clock (use_sim_time without
        # /clock stopped this timer, and the node fell silent)
        self.timer = node.create_timer(1.0 / config.control_rate_hz, self._tick,
                                       clock=Clock(clock_type=ClockType.STEADY_TIME))

    def _count(self, publisher: Publisher) -> None:
        publish, topic = publisher.publish, publisher.topic_name

        def counted(msg: Any) -> None:
            publish(msg)
            self.stats.publish(topic)

        publisher.publish = counted  # type: ignore[method-assign]

    def _tick(self) -> None:
        start = time.monotonic_ns()
        self.stats.tick(start)
        self.step()
        end = time.monotonic_ns()
        self.stats.done(end - start)
        if end >= self._next_log_ns:
            self._next_log_ns = end + round(self.config.jitter_log_period_s * NS_PER_S)
            self.node.get_logger().info(f'loop: {format_summary(self.stats.summary())}')

    def close(self) -> None:
        """Log the final statistics and write them to ``jitter_report_path`` if set."""
        summary = self.stats.summary()
        self.node.get_logger().info(f'loop at shutdown: {format_summary(summary)}')
        if self.config.jitter_report_path:
            self.stats.write(self.config.jitter_report_path, self.node.get_name())


def now_ns(node: Node) -> int:
    """The node clock's time, integer ns (wall time unless use_sim_time)."""
    return int(node.get_clock().now().nanoseconds)


SPIN_TIMEOUT_S = 0.1
"""Longest wait of one executor spin: bounds how late a node notices a stop request."""


PARENT_ENV = 'TRUST_AV_PARENT_PID'
"""Set by the orchestrator to its pid: a node started with it stops (cleanly, like on
SIGTERM) when that process is gone, so that a killed orchestrator leaves no node behind and
the recorder still finishes its bag."""
DRAIN_S = 0.3
"""On a stop request a node keeps taking what is already queued for this long."""
ACK_TIMEOUT_S = 1.0
"""Then it waits at most this long, over all its reliable publishers, until every matched
subscriber (the recorder) has acknowledged what it published."""


class GraphNode(Protocol):
    """What :func:`spin_node` needs of a node besides ``rclpy.node.Node``.

    Attributes:
        finished: set to True by a node that ends by itself (the recorder, once it holds
            every step); the loop then stops.
        exit_code: the process exit code once it ends (0, or e.g. the recorder's 3 for a
            full disk).
        stopping: set to True by :func:`spin_node` when a stop is requested, before the
            node takes what is still queued: from then on it finishes work in progress but
            starts none of its own (the step authority publishes no further step).
    """

    finished: bool
    exit_code: int
    stopping: bool

    def close(self) -> None:
        """Called once before the node is destroyed (finish files, write statistics)."""


def init_rclpy(args: list[str]) -> None:
    """``rclpy.init`` without rclpy's signal handlers; a command line rcl refuses (a params
    file it cannot parse, a bad ``-p``) becomes one line.

    Raises:
        ParamsError: rcl refused the arguments; the message is rcl's first line.
    """
    use_command_line(args)   # its -p rules win over the params files (ros/parameters.py)
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except _rclpy.RCLError as err:
        # e.g. "failed to initialize rcl: Couldn't parse params file: '--params-file F'.
        # Error: Will not support aliasing at line 4\n, at .../parse.c:893, at ..."
        first = str(err).splitlines()[0] if str(err) else type(err).__name__
        raise ParamsError(f'rcl refused the command line: {first.rstrip(", ")}') from err


def start_node(factory: Callable[[], Node], args: list[str] | None = None) -> Node:
    """Build a node and refuse it if it got an unknown parameter from its own section or
    ``-p`` (:func:`trust_av_common.ros.parameters.check_overrides`); needs ``rclpy.init``
    first. A managed node (:class:`trust_av_common.ros.lifecycle.ManagedNode`, which has a
    ``start`` method) runs the start-up transitions its ``autostart`` asks for instead; its
    ``configure`` makes the check. A node without its own ``/diagnostics`` status gets one
    saying it runs (:mod:`trust_av_common.ros.diagnostics`).

    Args:
        factory: builds the node.
        args: the command line given to ``rclpy.init`` (default: ``sys.argv``).

    Raises:
        ParamsError: a bad or unknown parameter (the node is closed and destroyed).
    """
    node = factory()
    command_line = list(sys.argv if args is None else args)
    try:
        start = getattr(node, 'start', None)
        if callable(start):   # a managed node: its configure checks the overrides
            start(command_line)
        else:
            check_overrides(node, command_line)
            if getattr(node, 'ready_line', ''):   # only once accepted (ManagedNode: configure)
                node.get_logger().info(node.ready_line)  # type: ignore[attr-defined]
    except BaseException:
        node.close()  # type: ignore[attr-defined]
        node.destroy_node()
        raise
    if getattr(node, 'diagnostics', None) is None:   # a managed node has its own
        node.diagnostics = NodeDiagnostics(  # type: ignore[attr-defined]
            node, 'node', lambda: (OK, 'running', {}))
    return node


def spin_node(factory: Callable[[], Node], args: list[str] | None = None,
              user_errors: tuple[type[BaseException], ...] = (ValueError,)) -> int:
    """A node's whole life, the three steps of ros2/examples with a safe stop::

        rclpy.init(args)                        # 1. init (no rclpy signal handler)
        node = factory()                        #    bad or unknown parameters -> one line,
                                                #    exit 2
        while not (stop requested or node.finished):
            executor.spin_once(0.1 s)           # 2. spin (EventsExecutor)
        node.close(); node.destroy_node(); rclpy.try_shutdown()   # 3. shut down

    ``factory`` builds a node that is also a :class:`GraphNode`. Start-up errors of the kinds
    in ``user_errors`` (bad parameters, an unreadable trace), and a parameter override that
    neither the node nor any node of the graph has (:func:`check_overrides`), are printed as
    one line and give exit code 2, and so do a component that fails to load or build
    (:class:`~trust_av_common.registry.RegistryError`) and, at any step, one that
    breaks its interface (:class:`~trust_av_common.component_checks.ComponentError`:
    the node then stops as on SIGTERM, its messages acknowledged); anything else propagates
    with its traceback, so the orchestrator can name the node that died. SIGINT, SIGTERM and
    SIGHUP (unless ignored, as under ``nohup``) end the node cleanly (its ``exit_code``), as
    does the death of the process named by :data:`PARENT_ENV`: the node
    first takes what is queued for :data:`DRAIN_S` and waits until its messages are
    acknowledged, so a recorder stopped after it holds them. While it drains, its
    ``stopping`` is set: the step authority starts no new step (it would otherwise keep the
    lock-step chain going for the whole drain, tens of steps a stopped run did not ask for,
    whose messages a recorder behind on a loaded machine had not acknowledged when their
    writers exited).

    Args:
        factory: builds the node (its constructor).
        args: command-line arguments for rclpy (default: ``sys.argv``).
        user_errors: exception types that mean bad input.

    Returns:
        The process exit code.
    """
    # SIGINT, SIGTERM and SIGHUP only *request* a stop; the loop below honours it between spins.
    # rclpy's own SIGINT handler shuts the context down asynchronously (which raced with the
    # next wait: "the given context is not valid"), and the EventsExecutor (C++) installs its
    # own SIGINT/SIGTERM handlers that do the same from inside spin_once. A KeyboardInterrupt
    # raised inside the executor's C++ code (e.g. while it registers the node's callbacks)
    # left callbacks registered and aborted the process at teardown ("Destroying callback
    # manager with callbacks remaining"). So no exception is ever raised into rclpy: the
    # handlers set a flag, spin_once returns within its timeout, and the finally block tears
    # down in order while the context is still valid. Set after the executor exists, so its
    # handlers are replaced; set explicitly, since a background process inherits SIGINT as
    # ignored.
    stop = {'requested': False}

    def request_stop(_signum: int, _frame: object) -> None:
        stop['requested'] = True

    try:
        init_rclpy(args if args is not None else sys.argv)
    except ParamsError as err:
        _say(f'error: {one_line(err)}')
        return 2
    node = None
    refused: tuple[type[BaseException], ...] = (
        *user_errors, ParamsError, RegistryError, InvalidParameterValueException,
        ParameterUninitializedException)
    executor = EventsExecutor()
    signal.signal(signal.SIGINT, request_stop)
    signal.signal(signal.SIGTERM, request_stop)
    if signal.getsignal(signal.SIGHUP) != signal.SIG_IGN:  # nohup asks to outlive the terminal
        signal.signal(signal.SIGHUP, request_stop)        # its terminal closed
    try:
        try:
            node = start_node(factory, args)
        except refused as err:
            _say(f'error: {one_line(err)}')
            return int(getattr(err, 'exit_code', 2))  # e.g. the recorder's disk-full code
        executor.add_node(node)
        graph_node: GraphNode = node  # type: ignore[assignment]
        parent = int(os.environ.get(PARENT_ENV, '0') or 0)
        try:
            while not stop['requested'] and ok() and not graph_node.finished:
                executor.spin_once(timeout_sec=SPIN_TIMEOUT_S)
                if parent and os.getppid() != parent:
                    stop['requested'] = True
        except ComponentError as err:   # a plug-in broke its interface: stop cleanly, exit 2
            _say(f'error: {one_line(err)}')
            graph_node.exit_code = 2
        if not graph_node.finished and ok():
            graph_node.stopping = True
            _hand_over(node)
            _drain(executor, node)
    except ExternalShutdownException:
        pass  # the context was shut down from outside: clean exit below
    finally:
        if node is not None:
            node.close()  # type: ignore[attr-defined]
            executor.remove_node(node)
        executor.shutdown()
        if node is not None:
            node.destroy_node()
        try_shutdown()
    return 0 if node is None else int(node.exit_code)  # type: ignore[attr-defined]


def _hand_over(node: Node) -> None:
    """On a stop request, an active managed node in wall mode is deactivated first, so that
    a vehicle gets its hand-over command
    (:meth:`trust_av_common.ros.lifecycle.ManagedNode.handover`) and the recorder still
    takes it while the node drains. In lock-step nothing is added:
    a stopped run records exactly the steps it made."""
    if getattr(node, 'active', False) and getattr(node, 'wall', False):
        node.trigger_deactivate()  # type: ignore[attr-defined]


def _say(line: str) -> None:
    """Print a node's one error line. Where even that cannot be written (its log is on the
    disk that filled up) the exit code is the only report, and the caller returns it."""
    with contextlib.suppress(OSError):
        print(line, file=sys.stderr, flush=True)


def _drain(executor: Executor, node: Node) -> None:
    """Take what is queued (:data:`DRAIN_S`), then wait for the acknowledgements of what
    this node published (:data:`ACK_TIMEOUT_S` over all publishers); a topic whose
    subscribers have not acknowledged everything by then is named in a warning.

    A reliable reader acknowledges when its writer's heartbeat asks, so this wait ends as
    soon as a heartbeat period allows: the run's Fast DDS profile
    (``config/fastdds_graph.xml``) sets it to 100 ms; with Fast DDS's default (3 s) the
    wait ran into its timeout on every stop, acknowledged or not.
    """
    end = time.monotonic() + DRAIN_S
    while time.monotonic() < end and ok():
        executor.spin_once(timeout_sec=0.02)
    wait_acked(node, node.publishers, 'stopping')


def wait_acked(node: Node, publishers: Iterable[Publisher], when: str) -> None:
    """Wait until every reliable subscriber has acknowledged what ``publishers`` sent
    (:data:`ACK_TIMEOUT_S` over all of them; a best-effort publisher returns at once), so
    that a message published just before the publisher is destroyed (a hand-over command at
    ``shutdown``, the last step at a stop) is delivered rather than dropped with its
    writer; a topic not acknowledged in time is named in a warning that starts ``when``."""
    deadline = time.monotonic() + ACK_TIMEOUT_S
    unacknowledged = []
    for publisher in publishers:
        left = max(0.0, deadline - time.monotonic())
        if not publisher.wait_for_all_acked(Duration(nanoseconds=int(left * 1e9))):
            unacknowledged.append(publisher.topic_name)
    if unacknowledged:
        node.get_logger().warning(
            f'{when}: not acknowledged by every subscriber within {ACK_TIMEOUT_S:g} s: '
            f'{", ".join(unacknowledged)}')
