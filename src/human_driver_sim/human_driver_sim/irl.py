"""Inverse optimal control of the driver MPC's feature weights W (Ozkan & Ma, eq. 13).

Method: inverse KKT (Keshavarz, Wang & Boyd 2011; Englert et al. 2017). A demonstration is
the state (gap, speed, leader speed), the leader plan the follower expects and the N
accelerations the follower then drove. With inactive bounds the driver's optimality condition
is sum_j w_j grad_u f_j = 0, linear in W; with the normalisation w_a = 1 the remaining three
weights are the non-negative least-squares solution of the stacked stationarity residuals.
The per-pair weights are the driver population's source; the shipped W, tau_H and d_s come
from the bounded replay fit (:mod:`human_driver_sim.fitting`), which uses
:func:`nelder_mead` below (scipy's).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import casadi as ca
import numpy as np

from human_driver_sim.car_following import FollowingPair
from human_driver_sim.driver_mpc import DriverConfig, features

__all__ = ['Demonstration', 'demonstrations', 'fit_inverse_kkt', 'nelder_mead']


@dataclass(frozen=True)
class Demonstration:
    """One step of demonstrated driving (SI units)."""

    gap_m: float
    speed_mps: float
    leader_speed_mps: float
    expected_mps2: np.ndarray
    accels_mps2: np.ndarray


def _gradient_function(config: DriverConfig) -> ca.Function:
    n = config.horizon_steps
    u = ca.SX.sym('u', n)
    expected = ca.SX.sym('e', n)
    state = ca.SX.sym('x', 3)
    feats = features(state[0], state[1], state[2], [u[k] for k in range(n)],
                     [expected[k] for k in range(n)], dt_s=config.dt_s,
                     standstill_gap_m=config.desired_standstill_gap_m,
                     time_headway_s=config.time_headway_s,
                     desired_speed_mps=config.speed_max_mps)
    jac = ca.jacobian(ca.vertcat(*feats), u)  # 4 x N
    return ca.Function('feature_jacobian', [state, u, expected], [jac])


def fit_inverse_kkt(config: DriverConfig, demos: Sequence[Demonstration]) -> np.ndarray:
    """Fit W = (1, w_ds, w_rs, w_rd) from demonstrations by inverse KKT.

    Raises:
        ValueError: No demonstrations.
    """
    if not demos:
        raise ValueError('inverse KKT needs at least one demonstration')
    jac = _gradient_function(config)
    blocks = [np.asarray(jac([d.gap_m, d.speed_mps, d.leader_speed_mps], d.accels_mps2,
                             d.expected_mps2)).T for d in demos]
    stacked = np.vstack(blocks)  # (N * demos) x 4
    scale = np.linalg.norm(stacked[:, 1:], axis=0)
    scale[scale == 0.0] = 1.0
    import scipy.optimize  # lazy: importing scipy costs every trust-av start

    rest = scipy.optimize.nnls(stacked[:, 1:] / scale, -stacked[:, 0])[0]
    return np.concatenate([[1.0], rest / scale])


def demonstrations(pair: FollowingPair, horizon_steps: int) -> list[Demonstration]:
    """Demonstrations from one recorded pair (already resampled to the control step).

    The plan the follower expects of its leader is a stand-in: constant acceleration at the
    leader's last observed acceleration (backward difference), as the planner's CA predictor.
    The demonstrated plan is the follower's next N realised accelerations.
    """
    dt = pair.dt_s
    accel = np.diff(pair.follower_speed_mps) / dt
    lead_accel = np.diff(pair.leader_speed_mps) / dt
    demos = []
    for k in range(1, len(accel) - horizon_steps + 1):
        demos.append(Demonstration(float(pair.gap_m[k]), float(pair.follower_speed_mps[k]),
                                   float(pair.leader_speed_mps[k]),
                                   np.full(horizon_steps, lead_accel[k - 1]),
                                   accel[k:k + horizon_steps].copy()))
    return demos


def nelder_mead(func: Callable[[np.ndarray], float], start: np.ndarray, *, step: float = 0.5,
                iterations: int = 60) -> tuple[np.ndarray, float]:
    """Derivative-free minimisation by Nelder-Mead (scipy.optimize.minimize), from the
    simplex ``start`` and ``start + step * e_i`` for ``iterations`` iterations (no other
    stopping rule, so a fit's length is the same on every machine).

    Returns:
        The best point found and its value.
    """
    origin = np.asarray(start, dtype=float)
    simplex = np.vstack([origin, origin + step * np.eye(origin.size)])
    import scipy.optimize  # lazy: importing scipy costs every trust-av start

    result = scipy.optimize.minimize(
        func, origin, method='Nelder-Mead',
        options={'initial_simplex': simplex, 'maxiter': iterations,
                 'maxfev': np.iinfo(np.int64).max, 'xatol': 0.0, 'fatol': 0.0})
    return np.asarray(result.x, dtype=float), float(result.fun)
