"""A trace replayed at real-time speed (wall-clock mode of the traffic node, shadow runs).

:class:`LeadReplay` gives the lead vehicle's odometry and speed preview at any elapsed wall
time of the run (speed linearly interpolated on the trace's grid, position its exact
integral), so a player can publish the latest state at its own rate.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from preceding_traffic.traces import SpeedTrace

__all__ = ['LeadReplay']


class LeadState(NamedTuple):
    """The replayed vehicle's odometry: position (m) and speed (m/s)."""

    position_m: float
    speed_mps: float


class LeadReplay:
    """The lead vehicle of a trace at elapsed time t (s since the first sample)."""

    def __init__(self, trace: SpeedTrace, initial_position_m: float) -> None:
        self.trace = trace
        self.times_s = np.arange(len(trace.speeds_mps)) * trace.dt_s
        speeds = np.asarray(trace.speeds_mps, dtype=float)
        segments = 0.5 * (speeds[1:] + speeds[:-1]) * trace.dt_s
        self.positions_m = initial_position_m + np.concatenate(([0.0], np.cumsum(segments)))
        self.duration_s = float(self.times_s[-1])

    def speed_mps(self, t_s: float | np.ndarray) -> np.ndarray:
        """Speed at elapsed time(s) ``t_s``; held after the end."""
        return np.asarray(np.interp(t_s, self.times_s, self.trace.speeds_mps), dtype=float)

    def state(self, t_s: float) -> LeadState:
        """Odometry at elapsed time ``t_s`` (clipped to the trace)."""
        t = min(max(t_s, 0.0), self.duration_s)
        k = min(int(t // self.trace.dt_s), len(self.times_s) - 2)
        tau = t - self.times_s[k]
        v0 = float(self.trace.speeds_mps[k])
        slope = (float(self.trace.speeds_mps[k + 1]) - v0) / self.trace.dt_s
        return LeadState(float(self.positions_m[k] + v0 * tau + 0.5 * slope * tau * tau),
                         float(self.speed_mps(t)))

    def preview(self, t_s: float, horizon: int, dt_s: float) -> np.ndarray:
        """Speeds at ``t_s + k dt_s``, k = 0..horizon-1, m/s."""
        return np.asarray(self.speed_mps(t_s + np.arange(horizon) * dt_s), dtype=float)
