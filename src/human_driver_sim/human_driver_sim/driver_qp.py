"""A fast, exact, batched path of :class:`~human_driver_sim.driver_mpc.DriverMpc` for data.

The driver's cost (eq. 13, :func:`~human_driver_sim.driver_mpc.features`) is a convex
quadratic in its plan u: under the explicit-Euler rollout every feature is a sum of
squares of affine functions of u, ``f_j = ||A_j u + b_j||^2``, where the A_j depend only on
dt, N and tau_H and the b_j on the state. So ``H = 2 sum_j w_j A_j^T A_j`` is one constant
matrix (positive definite: w_a > 0) and the unconstrained minimiser ``u* = -H^-1 g(state)``
is a linear law. It is the MPC's answer wherever it satisfies the MPC's constraints
(acceleration and speed bounds, the hard gap bound d^2..d^N >= ``standstill_gap_m``
against the cautious AV prediction); elsewhere
:class:`BatchDriver` asks :class:`DriverMpc` itself, row by row. Each row may have its own
v_max (the paper's v_max = max(v_PT) of the trace the vehicle follows, Table I).

``tests/core/test_driver_fit.py`` checks the two against each other on random states, near the
bounds too: if DriverMpc's constraints change, that test says so.

Rollout (:mod:`trust_av_common.kinematics`), for k = 1..N and the AV's speeds
r_0..r_{N-1} from its expected plan e::

    v_k = v_0 + dt sum_{i<k} u_i                       (L: ones on and below the diagonal)
    d_k = d_0 + dt sum_{m<k} (r_m - v_m)               = c_k - dt^2 sum_i max(0, k-1-i) u_i
    f_a = |u|^2,  f_ds = |v - v_max|^2,  f_rs = |r_{k-1} + e_{k-1} dt - v_k|^2,
    f_rd = |d - d_s - tau v|^2
"""

from __future__ import annotations

import dataclasses

import numpy as np

from human_driver_sim.driver_mpc import DriverConfig, DriverMpc, bound_av_accels

__all__ = ['BatchDriver']

_FEASIBILITY_TOL = 1e-9


class BatchDriver:
    """The driver MPC's plans for many states at once (rows), exact."""

    def __init__(self, config: DriverConfig) -> None:
        self.config = config
        n, dt = config.horizon_steps, config.dt_s
        k = np.arange(1, n + 1)[:, None]
        i = np.arange(n)[None, :]
        self._speed_map = dt * (i < k).astype(float)           # v = v0 + S u
        self._gap_map = -dt * dt * np.maximum(0, k - 1 - i)    # d = c + G u
        tau = config.time_headway_s
        self._a = {'a': np.eye(n), 'ds': self._speed_map, 'rs': -self._speed_map,
                   'rd': self._gap_map - tau * self._speed_map}
        w = config.weights
        self._w = dict(zip(('a', 'ds', 'rs', 'rd'), w, strict=True))
        hessian = 2.0 * sum(self._w[j] * self._a[j].T @ self._a[j] for j in self._a)
        self._inverse = np.linalg.inv(hessian)
        self._mpc: dict[float, DriverMpc] = {}
        self.fallbacks = 0
        """Rows answered by DriverMpc (a constraint binds)."""
        self.rows = 0

    def _offsets(self, gap: np.ndarray, speed: np.ndarray, av_speed: np.ndarray,
                 expected: np.ndarray, speed_max: np.ndarray) -> dict[str, np.ndarray]:
        c, n, dt = self.config, self.config.horizon_steps, self.config.dt_s
        # AV speeds at steps 0..N-1 and at the end of each step (f_rs), rows x N.
        av = av_speed[:, None] + dt * np.concatenate(
            [np.zeros((len(gap), 1)), np.cumsum(expected[:, :-1], axis=1)], axis=1)
        av_next = av + dt * expected
        steps = np.arange(1, n + 1)[None, :]
        gap_const = gap[:, None] + dt * np.cumsum(av, axis=1) - dt * steps * speed[:, None]
        return {'a': np.zeros((len(gap), n)), 'ds': speed[:, None] - speed_max[:, None]
                + np.zeros((1, n)),
                'rs': av_next - speed[:, None],
                'rd': gap_const - c.desired_standstill_gap_m - c.time_headway_s * speed[:, None],
                'gap_const': gap_const}

    def plans(self, gap_m: np.ndarray, speed_mps: np.ndarray, av_speed_mps: np.ndarray,
              expected_mps2: np.ndarray, speed_max_mps: np.ndarray | None = None) -> np.ndarray:
        """Plans DriverMpc.step would return, rows x N (m/s^2).

        Args:
            gap_m: Gaps to the vehicle ahead, m (rows).
            speed_mps: Own speeds, m/s (rows).
            av_speed_mps: Speeds of the vehicle ahead, m/s (rows).
            expected_mps2: Its expected plans, rows x N, m/s^2.
            speed_max_mps: v_max per row (the config's ``speed_max_mps`` if None), m/s.
        """
        c = self.config
        gap, speed, av = (np.asarray(x, dtype=float) for x in (gap_m, speed_mps, av_speed_mps))
        expected = np.asarray(expected_mps2, dtype=float)
        vmax = (np.full(len(gap), c.speed_max_mps) if speed_max_mps is None
                else np.asarray(speed_max_mps, dtype=float))
        b = self._offsets(gap, speed, av, expected, vmax)
        grad: np.ndarray = 2.0 * sum(self._w[j] * b[j] @ self._a[j] for j in self._a)
        plan: np.ndarray = -grad @ self._inverse.T
        speeds = speed[:, None] + plan @ self._speed_map.T
        # DriverMpc's hard gap bound: d^2..d^N >= d_s against the AV braking as
        # driver_mpc.bound_av_accels says, never reversing.
        bound_accels = bound_av_accels(c, expected)
        cautious = np.empty_like(expected)
        cautious[:, 0] = np.maximum(av, 0.0)
        for k in range(1, expected.shape[1]):
            cautious[:, k] = np.maximum(cautious[:, k - 1] + bound_accels[:, k - 1] * c.dt_s,
                                        0.0)
        steps = np.arange(1, expected.shape[1] + 1)[None, :]
        cautious_gaps = (gap[:, None] + c.dt_s * np.cumsum(cautious, axis=1)
                         - c.dt_s * steps * speed[:, None] + plan @ self._gap_map.T)
        tol = _FEASIBILITY_TOL
        ok = ((plan >= c.accel_min_mps2 - tol).all(axis=1)
              & (plan <= c.accel_max_mps2 + tol).all(axis=1)
              & (speeds >= c.speed_min_mps - tol).all(axis=1)
              & (speeds <= vmax[:, None] + tol).all(axis=1)
              & (cautious_gaps[:, 1:] >= c.standstill_gap_m + tol).all(axis=1))
        self.rows += len(gap)
        for row in np.flatnonzero(~ok):
            self.fallbacks += 1
            key = float(vmax[row])
            if key not in self._mpc:
                self._mpc[key] = DriverMpc(dataclasses.replace(c, speed_max_mps=key))
            mpc = self._mpc[key]
            mpc.reset()
            plan[row] = mpc.step(float(gap[row]), float(speed[row]), float(av[row]),
                                 expected[row]).plan_mps2
        return plan
