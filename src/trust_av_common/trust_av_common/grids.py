"""Values on time grids: a plan or preview given at its own times, read on another grid.

A longitudinal plan (``JointTrajectory``) carries its own times (``time_from_start``), so a
reader never has to assume the writer's step: the planner's plan and expected plan are on its
prediction grid (the control period at 10 Hz), the human driver model and the plan estimators
on the paper's 1 s grid. Accelerations are held between their times (each is applied until
the next, :func:`hold_at`); speeds are interpolated (:func:`interp_at`). Pure: no ROS.
"""

from __future__ import annotations

import numpy as np

__all__ = ['grid_times', 'hold_at', 'interp_at']

TIME_TOLERANCE_S = 1e-9
"""Times closer than this are the same instant (grids built from floats, ns durations)."""


def grid_times(step_s: float, steps: int) -> np.ndarray:
    """Times k * step_s, k = 0..steps-1, s."""
    return np.arange(steps) * step_s


def _checked(times_s: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    times = np.asarray(times_s, dtype=float)
    vals = np.asarray(values, dtype=float)
    if vals.size == 0 or times.shape != vals.shape:
        raise ValueError(f'need as many times as values (> 0), got {times.size} and {vals.size}')
    if np.any(np.diff(times) <= 0.0):
        raise ValueError(f'times must increase, got {times.tolist()}')
    return times, vals


def _same_grid(times: np.ndarray, step_s: float, steps: int) -> bool:
    return times.size == steps and bool(np.all(np.abs(times - grid_times(step_s, steps))
                                               <= TIME_TOLERANCE_S))


def hold_at(times_s: np.ndarray, values: np.ndarray, step_s: float, steps: int) -> np.ndarray:
    """Values each held from its time to the next (zero-order hold), read at k * step_s,
    k = 0..steps-1; the first value before its time, the last one after the end.

    Returns a copy of ``values`` when ``times_s`` is that grid already.

    Raises:
        ValueError: no values, lengths that differ, or times that do not increase.
    """
    times, vals = _checked(times_s, values)
    if _same_grid(times, step_s, steps):
        return vals.copy()
    index = np.searchsorted(times, grid_times(step_s, steps) + TIME_TOLERANCE_S,
                            side='right') - 1
    held: np.ndarray = vals[np.clip(index, 0, vals.size - 1)]
    return held


def interp_at(times_s: np.ndarray, values: np.ndarray, step_s: float,
              steps: int) -> np.ndarray:
    """Values linearly interpolated at k * step_s, k = 0..steps-1; the first value before
    its time, the last one after the end.

    Returns a copy of ``values`` when ``times_s`` is that grid already.

    Raises:
        ValueError: no values, lengths that differ, or times that do not increase.
    """
    times, vals = _checked(times_s, values)
    if _same_grid(times, step_s, steps):
        return vals.copy()
    out: np.ndarray = np.interp(grid_times(step_s, steps), times, vals)
    return out
