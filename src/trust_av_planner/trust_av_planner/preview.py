"""The lead's speed over the NMPC's horizon, and plans moved between time grids.

A preview is what the planner assumes the preceding vehicle does over the horizon
(parameter ``lead_preview``):

- ``recorded``: a speed preview received from outside (the replayed recording's future, or
  V2V), interpolated onto the prediction grid
  (:func:`trust_av_common.grids.interp_at`);
- ``constant_speed``: the lead keeps its current speed;
- ``constant_acceleration``: the lead keeps its recent acceleration, its speed change over the
  last ``lead_accel_window_s`` (:class:`LeadPreview`), and stops at 0 m/s.

The last two need only the lead's odometry, which a vehicle's perception gives. Grids: the
plan estimators work on the model step (the paper's 1 s); their plans are held (zero-order
hold, :func:`hold_on_grid`) onto the NMPC's prediction grid; the explicability score does not
see the hold itself: the Tanimoto distance of two plans repeated m times each is the distance
of the plans.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from trust_av_common.grids import grid_times, hold_at

__all__ = ['LeadPreview', 'hold_on_grid']


def hold_on_grid(values: np.ndarray, source_step_s: float, step_s: float, steps: int,
                 offset_s: float = 0.0) -> np.ndarray:
    """A plan of accelerations each held for ``source_step_s`` (zero-order hold) that began
    ``offset_s`` ago, read at k * step_s from now, k = 0..steps-1; the last value is held
    past the end. A copy of ``values`` when the grids are the same and the offset is 0."""
    vals = np.asarray(values, dtype=float)
    return hold_at(grid_times(source_step_s, vals.size) - offset_s, vals, step_s, steps)


class LeadPreview:
    """A preview built from the lead's odometry (``constant_speed`` or
    ``constant_acceleration``).

    Args:
        mode: ``constant_speed`` or ``constant_acceleration``.
        window_s: the acceleration is the speed change over (about) this window, s.

    Raises:
        ValueError: unknown mode or a window that is not > 0.
    """

    def __init__(self, mode: str, window_s: float) -> None:
        if mode not in ('constant_speed', 'constant_acceleration'):
            raise ValueError(f'a preview from odometry is constant_speed or '
                             f'constant_acceleration, got {mode!r}')
        if not window_s > 0.0:
            raise ValueError(f'window_s must be > 0, got {window_s}')
        self.mode = mode
        self.window_s = window_s
        self._speeds: deque[tuple[float, float]] = deque()

    def reset(self) -> None:
        """Forget the lead's history."""
        self._speeds.clear()

    def observe(self, t_s: float, speed_mps: float) -> None:
        """The lead's speed at time ``t_s`` (s); an older sample than the latest is ignored,
        one at the same time replaces it."""
        if self._speeds and t_s < self._speeds[-1][0]:
            return
        if self._speeds and t_s == self._speeds[-1][0]:
            self._speeds.pop()
        self._speeds.append((t_s, speed_mps))
        while len(self._speeds) > 2 and self._speeds[1][0] <= t_s - self.window_s:
            self._speeds.popleft()

    def acceleration_mps2(self) -> float:
        """The lead's acceleration: speed change over the window (0 with one sample)."""
        if len(self._speeds) < 2:
            return 0.0
        (t0, v0), (t1, v1) = self._speeds[0], self._speeds[-1]
        return (v1 - v0) / (t1 - t0)

    def preview(self, step_s: float, steps: int) -> np.ndarray:
        """The lead's speed at k * step_s from its latest sample, k = 0..steps-1, m/s.

        Raises:
            ValueError: nothing observed yet.
        """
        if not self._speeds:
            raise ValueError('no lead odometry observed yet')
        speed = self._speeds[-1][1]
        if self.mode == 'constant_speed':
            return np.full(steps, speed)
        out: np.ndarray = np.maximum(speed + self.acceleration_mps2()
                                     * grid_times(step_s, steps), 0.0)
        return out
