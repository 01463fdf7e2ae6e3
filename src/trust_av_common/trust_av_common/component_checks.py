"""What a component (a plug-in of :mod:`trust_av_common.registry`) gives the loop is
checked where it enters, every step: the one place both the in-process simulator and the
nodes go through.

A component is code from outside: its output is input. Each call into it goes through
:func:`call` (anything it raises, ``SystemExit`` included, becomes a
:class:`ComponentError` naming it; ``KeyboardInterrupt`` passes) and each value it returns
through :func:`check_plan` or :func:`check_number` (type, shape, finite, within the bounds
its group's interface documents). A violation is one line naming the component, its
group, the step and the bad value::

    predictor 'nan_plans' (trust_av.predictors) at step 3: plan[0] = nan is not finite

The callers (the group's own code, shared by the loop and the node) are
:class:`~trust_av_planner.planner.AvPlanner` (plan estimators),
:class:`~trust_monitor.paper_trust.TrustEstimator` and the NMPC's trust bound (trust models)
and :func:`~human_driver_sim.followers.make_follower` (followers); the step is the
component's own count of steps, 0 for its first. Pure: no ROS, numpy only.
"""

from __future__ import annotations

import numbers
from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np

from trust_av_common.errors import one_line
from trust_av_common.registry import RegistryError, describe

__all__ = ['BOUND_TOLERANCE', 'PASSING', 'ComponentError', 'call', 'check_number', 'check_plan',
           'check_type', 'raised']

T = TypeVar('T')

BOUND_TOLERANCE = 1e-6
"""How far past a documented bound a value may lie and still pass (solver round-off: a QP
solution sits on its bound within ~1e-9; 1e-6 m/s^2 is still far below anything that
matters physically)."""

SHOWN_CHARS = 80
"""At most this much of a bad output's text goes into the message."""


class ComponentError(RegistryError):
    """A component broke its interface while running: it raised, exited, or returned a
    value of the wrong type or shape, not finite, or outside its bounds. The message is one
    line naming the component, its group, the step and the bad value.

    Attributes:
        partial: what the run had recorded before the step (set by the caller that keeps
            it, e.g. the in-process simulator's result so far), else None.
    """

    partial: Any = None


PASSING = (KeyboardInterrupt, ComponentError)
"""What a call into a component lets through as it is: a stop request, and a check that
already failed inside it."""

def _short(value: Any) -> str:
    text = ' '.join(repr(value).split())
    return text if len(text) <= SHOWN_CHARS else text[:SHOWN_CHARS - 3] + '...'


def _fail(group: str, name: str, step: int, problem: str) -> ComponentError:
    return ComponentError(f'{describe(group, name)} at step {step}: {problem}')


def raised(group: str, name: str, step: int, what: str, err: BaseException) -> ComponentError:
    """The one line for ``err``, raised by component ``name`` in the call ``what``::

        try:
            value = component.predict()
        except PASSING:
            raise
        except BaseException as err:   # SystemExit too
            raise raised(group, name, step, 'predict()', err) from err

    (the loop's wrappers write the call out so: a ``try`` costs nothing until it raises).
    """
    return _fail(group, name, step, f'{what} raised {type(err).__name__}: {one_line(err)}')


def call(group: str, name: str, step: int, what: str, function: Callable[..., T],
         *args: Any) -> T:
    """``function(*args)``, a call into component ``name``: whatever it raises (an
    ``Exception``, ``SystemExit``) is a :class:`ComponentError` naming the component and
    the call (:func:`raised`); ``KeyboardInterrupt`` (a stop request) and a
    :class:`ComponentError` pass.

    Args:
        group: the component's entry-point group.
        name: its registered name.
        step: its step count (0: the first step).
        what: the call, as the message names it (``'predict()'``).
        function: the bound method to call.
    """
    try:
        return function(*args)
    except PASSING:
        raise
    except BaseException as err:
        raise raised(group, name, step, what, err) from err


def check_plan(value: Any, *, group: str, name: str, step: int, steps: int, low: float,
               high: float, what: str = 'plan') -> np.ndarray:
    """A plan (accelerations over a horizon) a component returned, as a float array.

    Args:
        value: what it returned.
        group, name, step: the component and its step (for the message).
        steps: the horizon it must cover (the shape is ``(steps,)``).
        low, high: its documented bounds, m/s^2 (:data:`BOUND_TOLERANCE` past them passes).
        what: the value's name in the message.

    Raises:
        ComponentError: not an array of real numbers, of another shape, not finite, or out
            of bounds.
    """
    # The usual case, in a few hundred ns: a float64 array of the right shape whose sum is
    # finite (NaN and inf propagate into it) within the bounds; numpy's reductions cost
    # microseconds each on arrays this small, Python's builtins on its list a tenth.
    if type(value) is np.ndarray and value.dtype is _FLOAT and value.shape == (steps,):
        values = value.tolist()
        total = sum(values)
        if total - total == 0.0 and min(values) >= low - BOUND_TOLERANCE and \
                max(values) <= high + BOUND_TOLERANCE:
            return value
    return _checked_plan(value, group, name, step, steps, low, high, what)


_FLOAT = np.dtype(np.float64)


def _checked_plan(value: Any, group: str, name: str, step: int, steps: int, low: float,
                  high: float, what: str) -> np.ndarray:
    """:func:`check_plan` for anything but a good float64 array: converted, or the one
    line that says what is wrong with it."""
    try:
        array = np.asarray(value)
    except (ValueError, TypeError) as err:
        raise _fail(group, name, step, f'{what} {_short(value)} is not an array of numbers '
                                       f'({one_line(err)})') from err
    if array.dtype.kind not in 'iuf':
        raise _fail(group, name, step, f'{what} {_short(value)} ({type(value).__name__} of '
                                       f'{array.dtype}) is not an array of real numbers')
    if array.shape != (steps,):
        raise _fail(group, name, step, f'{what} has shape {array.shape}, expected ({steps},) '
                                       f'(one value per horizon step): {_short(value)}')
    plan = array.astype(float)
    finite = np.isfinite(plan)
    if not finite.all():
        k = int(np.argmin(finite))
        raise _fail(group, name, step, f'{what}[{k}] = {float(plan[k])} is not finite')
    if plan.min() < low - BOUND_TOLERANCE or plan.max() > high + BOUND_TOLERANCE:
        k = int(np.argmin(plan)) if plan.min() < low - BOUND_TOLERANCE else int(np.argmax(plan))
        raise _fail(group, name, step, f'{what}[{k}] = {float(plan[k])!r} is outside its bounds '
                                       f'[{low:g}, {high:g}] m/s^2')
    return plan


def check_number(value: Any, *, group: str, name: str, step: int, what: str,
                 low: float | None = None, high: float | None = None) -> float:
    """A real number a component returned (not a bool), finite, within ``[low, high]``
    (None: unbounded on that side), as a float.

    Raises:
        ComponentError: not a real number, not finite, or out of bounds.
    """
    if type(value) is not float:   # the usual case skips the type tests
        if isinstance(value, _NOT_REAL) or not isinstance(value, numbers.Real):
            raise _fail(group, name, step, f'{what} {_short(value)} ({type(value).__name__}) '
                                           'is not a real number')
        value = float(value)
    if value - value != 0.0:       # NaN and inf
        raise _fail(group, name, step, f'{what} = {value} is not finite')
    if (low is not None and value < low) or (high is not None and value > high):
        bounds = f'[{"-inf" if low is None else f"{low:g}"}, ' \
                 f'{"inf" if high is None else f"{high:g}"}]'
        raise _fail(group, name, step, f'{what} = {value!r} is outside its bounds {bounds}')
    return value  # type: ignore[no-any-return]


_NOT_REAL = (bool, np.bool_)


def check_type(value: Any, kind: type | tuple[type, ...], *, group: str, name: str, step: int,
               what: str) -> Any:
    """``value`` if it is a ``kind``.

    Raises:
        ComponentError: it is not.
    """
    if not isinstance(value, kind):
        wanted = kind.__name__ if isinstance(kind, type) else \
            ' or '.join(k.__name__ for k in kind)
        raise _fail(group, name, step, f'{what} {_short(value)} ({type(value).__name__}) is '
                                       f'not a {wanted}')
    return value
