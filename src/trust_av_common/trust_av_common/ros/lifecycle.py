"""Managed (lifecycle) nodes: the planner and the trust monitor are
``rclpy.lifecycle.LifecycleNode``s (ROS 2's managed nodes,
https://design.ros2.org/articles/node_lifecycle.html).

What each transition does here (:class:`ManagedNode`):

- ``configure``: the subclass's :meth:`ManagedNode.build` declares and validates the
  parameters, builds the core, the publishers (``LifecyclePublisher``: silent until active),
  the subscriptions and the wall loop's timer (stopped); then unknown overrides are refused
  (:func:`trust_av_common.ros.parameters.check_overrides`). A refused value makes the
  transition fail (``unconfigured`` again) with one line in the log naming it; the process
  goes on.
- ``activate``: the publishers are enabled and the wall loop's timer starts.
- ``deactivate``: :meth:`ManagedNode.handover` publishes what hands the vehicle over (the
  planner: one command of its ``stale_decel_mps2``), then the publishers are disabled and the
  timer stopped.
- ``cleanup`` / ``shutdown`` (and an error): everything ``configure`` made is destroyed and
  the wall loop's statistics are written.

An exception raised in a subscription or timer callback of a node in ``clock_mode: wall``
(an internal error: the messages' values are checked before, :mod:`trust_av_common.envelope`)
never leaves the callback (:meth:`ManagedNode.internal_error`): it is logged with its
traceback, counted and reported as ERROR on ``/diagnostics``, and an active node is
deactivated at once, which publishes its hand-over command (the planner: one
``stale_decel_mps2``); the node then waits ``inactive`` until a lifecycle manager or an
operator activates it again (docs/operations/failures.md). A
:class:`~trust_av_common.component_checks.ComponentError` (a plug-in that broke its
interface) still ends the process with exit 2 after the same hand-over
(:func:`trust_av_common.ros.spin.spin_node`); in lock-step (a simulation) an exception ends
the process with its traceback, so the orchestrator names the node.

rclpy runs a transition's callback inside ``LifecycleNodeMixin.__change_state``
(``rclpy/lifecycle/node.py``): a callback's return value SUCCESS/FAILURE/ERROR picks the
next state (rcl_lifecycle ``default_state_machine.c``: FAILURE of ``configure`` returns to
``unconfigured``, ERROR goes through ``errorprocessing``), and an exception raised by the
callback is swallowed there into ERROR without a log. So the callbacks here catch every
exception, log it (one line for bad input, the traceback for anything else) and return the
code. A transition that is not valid from the current state (``activate`` while
``unconfigured``) makes rcl_lifecycle's ``rcl_lifecycle_trigger_transition_by_id`` fail
("Transition is not registered", ``rcl_lifecycle/src/rcl_lifecycle.c``), which rclpy 7.1
raises as ``RCLError`` out of its ``change_state`` service callback, ending the process: the
service here answers ``success`` False instead and logs a warning, as an rclcpp lifecycle
node does.

Start-up (:meth:`ManagedNode.start`, called by :func:`trust_av_common.ros.spin.start_node`):
with ``autostart: true`` (the shipped value) the node configures itself (a refused
parameter raises, so the process ends with one line and exit 2 as any node's) and, in
``clock_mode: lockstep``, activates itself: a ``trust-av run`` graph behaves exactly as with
plain nodes. In ``clock_mode: wall`` it waits ``inactive`` for ``activate``. With
``autostart: false`` it waits ``unconfigured`` for ``configure``.
"""

from __future__ import annotations

import functools
import traceback
from collections import Counter
from collections.abc import Callable
from typing import Any

from rclpy.exceptions import InvalidParameterValueException, ParameterUninitializedException
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.lifecycle import (
    LifecycleNode,
    LifecyclePublisher,
    LifecycleState,
    TransitionCallbackReturn,
)

from trust_av_common.component_checks import PASSING
from trust_av_common.errors import one_line
from trust_av_common.params import ParamsError
from trust_av_common.registry import RegistryError
from trust_av_common.ros import diagnostics as diag
from trust_av_common.ros.diagnostics import NodeDiagnostics, Report
from trust_av_common.ros.parameters import check_overrides
from trust_av_common.ros.raw_inputs import check_input_types
from trust_av_common.ros.spin import WallLoop, wait_acked

__all__ = ['ManagedNode']

SUCCESS = TransitionCallbackReturn.SUCCESS
FAILURE = TransitionCallbackReturn.FAILURE
ERROR = TransitionCallbackReturn.ERROR


class ManagedNode(LifecycleNode):
    """A graph node (:class:`trust_av_common.ros.spin.GraphNode`) run as a managed node.

    A subclass declares ``self.lifecycle`` (``LifecycleConfig``) in its constructor and
    implements :meth:`build`; it may set ``self.loop`` (a :class:`WallLoop`) and ``self.wall``
    there, override :meth:`handover` and :meth:`release`, and gate its own steps on
    ``self.active``.

    Attributes:
        active: the node is in the ``active`` state (its steps run and publish).
        configured: :meth:`build` succeeded and :meth:`release` has not run since: the
            core exists. An input callback tests it first and drops the message if not: the
            executor still delivers a message it took before ``cleanup`` or ``shutdown``
            destroyed the subscription (seen under a lifecycle manager with inputs at
            100 Hz: an ``AttributeError`` out of the callback ended the node).
        wall: ``clock_mode`` is ``wall`` (set by :meth:`build`).
        configure_error: why the last ``configure`` failed (None if it did not).
        refusals: input name -> messages dropped for their values (:meth:`refuse`).
        fault: the internal error that deactivated the node ('' once activated again).
        faults: internal errors caught since start (:meth:`internal_error`).
    """

    user_errors: tuple[type[BaseException], ...] = (ValueError,)
    """Exceptions of :meth:`build` that mean bad input (one line, not a traceback)."""
    task = 'node'
    """What its ``/diagnostics`` status is about (after the node's name)."""
    idle = 'inactive: waiting for activate'
    """Its ``/diagnostics`` message while inactive."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.finished = False  # runs until it is stopped (trust_av_common.ros.spin.GraphNode)
        self.stopping = False  # set by spin_node on a stop request
        self.exit_code = 0
        self.active = False
        self.configured = False
        self.wall = False
        self.loop: WallLoop | None = None
        self.configure_error: BaseException | None = None
        self.ready_line = ''  # set by build(), logged once configure has accepted everything
        self.command_line: list[str] = []
        self._quiet = False   # start(): the caller reports a failed configure itself
        self.blocked = ''     # why it cannot run as configured (clock_problem), '' if it can
        self.dropped = 0      # malformed input messages dropped (trust_av_common.ros.raw_inputs)
        self.wrong_types: dict[str, str] = {}   # input topic -> its publishers of another type
        self.typed_inputs: list[tuple[Any, str]] = []   # (subscription, type): raw_inputs
        self.refusals: Counter[str] = Counter()
        self.last_refusal = ''
        self.fault = ''
        self.faults = 0
        self._fault_logged = ''
        # in every state, from construction (a regular publisher: kept across cleanup)
        self.diagnostics = NodeDiagnostics(self, self.task, self.diagnose)
        self._base = (set(self.publishers), set(self.subscriptions), set(self.timers))
        service = self._service_change_state
        service.callback = self._refusing_invalid(service.callback)

    def _refusing_invalid(self, change_state: Any) -> Any:
        """rclpy's ``change_state`` service callback, answering ``success`` False for a
        transition not valid from the current state (see the module docstring)."""
        def guarded(request: Any, response: Any) -> Any:
            try:
                return change_state(request, response)
            except _rclpy.RCLError as err:
                label = request.transition.label or f'id {request.transition.id}'
                self.get_logger().warning(
                    f'transition {label} refused in state '
                    f'{self._state_machine.current_state[1]}: {str(err).splitlines()[0]}')
                response.success = False
                return response
        return guarded

    def create_subscription(self, msg_type: Any, topic: str, callback: Callable[[Any], None],
                            qos_profile: Any, **options: Any) -> Any:
        """``Node.create_subscription`` with the callback guarded (:meth:`internal_error`)."""
        return super().create_subscription(msg_type, topic, self._guarded(callback),
                                           qos_profile, **options)

    def create_timer(self, timer_period_sec: float, callback: Callable[[], Any],
                     callback_group: Any = None, clock: Any = None,
                     autostart: bool = True) -> Any:
        """``Node.create_timer`` with the callback guarded (:meth:`internal_error`)."""
        return super().create_timer(timer_period_sec, self._guarded(callback),
                                    callback_group=callback_group, clock=clock,
                                    autostart=autostart)

    def _guarded(self, callback: Callable[..., Any]) -> Callable[..., Any]:
        @functools.wraps(callback)
        def guarded(*args: Any) -> Any:
            try:
                return callback(*args)
            except PASSING:
                raise
            except Exception as err:
                if not getattr(self, 'wall', False):   # lock-step: the process ends, the
                    # orchestrator names the node
                    raise
                self.internal_error(err)
                return None
        return guarded

    def internal_error(self, err: Exception) -> None:
        """Wall mode: an exception of a callback or a timer. Logged (the traceback the first
        time a fault is seen, then one line at most every 5 s), counted, ERROR on
        ``/diagnostics`` until the next ``activate``; an active node is deactivated, which
        hands over (:meth:`handover`)."""
        self.faults += 1
        self.fault = f'{type(err).__name__}: {one_line(err)}'
        was_active = self.active
        what = 'handing over and deactivating' if was_active else 'not active'
        if self.fault != self._fault_logged:
            self._fault_logged = self.fault
            self.get_logger().error(f'internal error ({what}): {self.fault}\n'
                                    + traceback.format_exc())
        else:
            self.get_logger().error(f'internal error again ({what}; {self.faults} so far): '
                                    f'{self.fault}', throttle_duration_sec=5.0)
        if was_active:
            self.trigger_deactivate()
        try:
            self.diagnostics.changed()
        except Exception:   # the status itself fails: its timer reports it again
            self.get_logger().error('diagnostics failed:\n' + traceback.format_exc(),
                                    throttle_duration_sec=5.0)

    def refuse(self, name: str, topic: str, problem: str) -> None:
        """A message of input ``name`` dropped for its values (``problem``: one line naming
        the field): counted, named on ``/diagnostics`` and in a log line (at most one a
        second)."""
        self.refusals[name] += 1
        self.last_refusal = f'{name}: {problem}'
        self.get_logger().warning(
            f'refused a message on {topic} ({sum(self.refusals.values())} refused so far): '
            f'{problem}', throttle_duration_sec=1.0)
        self.diagnostics.changed()

    def build(self) -> None:
        """Declare and validate the parameters, build the core, publishers, subscriptions.

        Raises:
            ValueError: a refused parameter (any of :attr:`user_errors`).
        """
        raise NotImplementedError

    def handover(self) -> None:
        """Publish what hands control over on ``deactivate`` (default: nothing)."""

    def release(self) -> None:
        """Drop the core built by :meth:`build` (the entities are destroyed by the caller)."""

    def resume(self) -> None:
        """Called at the end of ``activate`` (default: nothing; lock-step: the steps whose
        inputs came while inactive)."""

    def health(self) -> Report:
        """The configured node's own (level, message, values) for ``/diagnostics``."""
        return diag.OK, 'configured', {}

    def diagnose(self) -> Report:
        """The ``/diagnostics`` status (:mod:`trust_av_common.ros.diagnostics`): the lifecycle
        state, why it does not run if it cannot (:meth:`clock_problem`, a failed
        ``configure``), else :meth:`health` while active; while configured, a publisher of
        another type on an input at least
        WARN, named in the message and in ``wrong_type_on_<topic>``
        (:func:`~trust_av_common.ros.raw_inputs.check_input_types`, asked here)."""
        level, message, values = self._state_report()
        if not self.configured:
            return level, message, values
        check_input_types(self)
        for topic, publishers in sorted(self.wrong_types.items()):
            level = max(level, diag.WARN)
            message += f'; {topic}: not connected to {publishers} (another type)'
            values[f'wrong_type_on_{topic}'] = publishers
        return level, message, values

    def _state_report(self) -> Report:
        state = str(self._state_machine.current_state[1])
        values = {'lifecycle_state': state, 'dropped_messages': str(self.dropped),
                  'refused_messages': str(sum(self.refusals.values())),
                  **{f'refused_{name}': str(n) for name, n in sorted(self.refusals.items())},
                  'last_refused': self.last_refusal or 'none',
                  'internal_errors': str(self.faults)}
        if not self.configured:
            error = self.configure_error
            if error is not None:
                return diag.ERROR, f'not running: configure failed: {one_line(error)}', values
            waiting = f'{state}: waiting for configure' if state == 'unconfigured' else state
            return diag.OK, waiting, values
        problem = self.clock_problem()
        level, message, more = self.health()
        values.update(more)
        if problem:
            return diag.ERROR, f'not running: {problem}', values
        if self.fault:
            return (diag.ERROR, f'internal error, handed over, inactive until activate: '
                    f'{self.fault}', values)
        if not self.active:
            return diag.OK, self.idle, values
        return level, message, values

    def clock_problem(self) -> str:
        """Why the node's clock does not fit ``clock_mode`` ('' if it does): wall mode
        stamps its outputs with the node's clock and times its inputs on the system's, so it
        needs ``use_sim_time`` false."""
        if not self.wall or not self.get_parameter('use_sim_time').value:
            return ''
        if self.get_clock().now().nanoseconds == 0:
            return ('use_sim_time is true and no clock is published on /clock: clock_mode wall '
                    'runs on the system clock (set use_sim_time false)')
        return ('use_sim_time is true and a simulated clock is published on /clock: '
                'clock_mode wall runs on the system clock (set use_sim_time false, or '
                'clock_mode lockstep to follow a simulation)')

    def check_clock(self) -> bool:
        """Wall mode, each tick: whether the node can run; a change is logged once (an
        error naming the problem, or that it is gone) and put on ``/diagnostics`` at once."""
        problem = self.clock_problem()
        if problem != self.blocked:
            if problem:
                self.get_logger().error(f'not running: {problem}')
            else:
                self.get_logger().info('clock fits clock_mode wall again: running')
            self.blocked = problem
            self.diagnostics.changed()
        return not problem

    def start(self, args: list[str]) -> None:
        """The start-up transitions ``autostart`` asks for (see the module docstring).

        Args:
            args: the node's command line (for the unknown-override check).

        Raises:
            ParamsError: ``configure`` failed on bad input (its exception: ValueError and
                the subclass's :attr:`user_errors` are re-raised as they are).
            RuntimeError: ``configure`` or ``activate`` failed otherwise.
        """
        self.command_line = list(args)
        if not self.lifecycle.autostart:  # type: ignore[attr-defined]
            self.get_logger().info('unconfigured: waiting for configure (autostart false)')
            return
        self._quiet = True
        try:
            if self.trigger_configure() != SUCCESS:
                if self.configure_error is not None:
                    raise self.configure_error
                raise RuntimeError('configure failed')
        finally:
            self._quiet = False
        if self.wall:
            self.get_logger().info('inactive: waiting for activate (clock_mode wall)')
        elif self.trigger_activate() != SUCCESS:
            raise RuntimeError('activate failed')

    def close(self) -> None:
        """At process end: the wall loop's jitter statistics (if still configured)."""
        if self.loop is not None:
            self.loop.close()
            self.loop = None

    # --- transitions (called by rclpy) ---

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.configure_error = None
        refused: tuple[type[BaseException], ...] = (
            *self.user_errors, ParamsError, RegistryError, InvalidParameterValueException,
            ParameterUninitializedException)
        try:
            self.build()
            check_overrides(self, self.command_line)
        except refused as err:
            return self._failed(err, FAILURE, one_line(err))
        except Exception as err:   # logged with its traceback, re-raised by start()
            return self._failed(err, ERROR, traceback.format_exc())
        if self.loop is not None:
            self.loop.timer.cancel()
        self.configured = True
        if self.ready_line:   # not before: a refused configure says nothing about being ready
            self.get_logger().info(self.ready_line)
        return super().on_configure(state)

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        result = super().on_activate(state)   # enables the LifecyclePublishers
        self.active = True
        self.fault = ''
        if self.loop is not None:
            self.loop.timer.reset()
        self.get_logger().info('active')
        self.resume()
        self.diagnostics.changed()
        return result

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        return self._deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._release()
        return super().on_cleanup(state)

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        if self.active:
            self._deactivate(state)
        self._release()
        return super().on_shutdown(state)

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.active = False
        self._release()
        return SUCCESS   # errorprocessing -> unconfigured

    # --- helpers ---

    def _deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        try:
            self.handover()
        except Exception:   # the publishers are disabled all the same
            self.get_logger().error('handover failed:\n' + traceback.format_exc())
        self.active = False
        if self.loop is not None:
            self.loop.timer.cancel()
        result = super().on_deactivate(state)
        self.get_logger().info('inactive')
        self.diagnostics.changed()
        return result

    def _failed(self, err: BaseException, code: Any, text: str) -> TransitionCallbackReturn:
        self.configure_error = err
        if not self._quiet:
            self.get_logger().error(f'configure failed: {text}')
        self._release()
        return code

    def _release(self) -> None:
        """Destroy what ``configure`` made (timers, subscriptions, publishers) and the core."""
        self.configured = False
        self.close()
        publishers, subscriptions, timers = self._base
        self.wrong_types.clear()
        self.typed_inputs.clear()
        for timer in [t for t in self.timers if t not in timers]:
            self.destroy_timer(timer)
        for sub in [s for s in self.subscriptions if s not in subscriptions]:
            self.destroy_subscription(sub)
        made = [p for p in self.publishers if p not in publishers]
        wait_acked(self, made, 'releasing')   # e.g. the hand-over of a shutdown from active
        for pub in made:
            if isinstance(pub, LifecyclePublisher):
                self.destroy_lifecycle_publisher(pub)
            else:
                self.destroy_publisher(pub)
        self.release()
        self.diagnostics.changed()
