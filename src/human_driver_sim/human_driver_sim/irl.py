"""Inverse optimal control of the driver MPC's feature weights W (Ozkan & Ma, eq. 13).

Method: inverse KKT (Keshavarz, Wang & Boyd 2011; Englert et al. 2017). A demonstration is
the state (gap, speed, leader speed), the leader plan the follower expects and the N
accelerations the follower then drove. With inactive bounds the driver's optimality condition
is sum_j w_j grad_u f_j = 0, linear in W; with the normalisation w_a = 1 the remaining three
weights are the non-negative least-squares solution of the stacked stationarity residuals.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import casadi as ca
import numpy as np

from human_driver_sim.driver_mpc import DriverConfig, features


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
                     standstill_gap_m=config.standstill_gap_m,
                     time_headway_s=config.time_headway_s,
                     desired_speed_mps=config.speed_max_mps)
    jac = ca.jacobian(ca.vertcat(*feats), u)  # 4 x N
    return ca.Function('feature_jacobian', [state, u, expected], [jac])


def _nnls(a: np.ndarray, b: np.ndarray, iterations: int = 5000) -> np.ndarray:
    """Non-negative least squares by projected gradient (no scipy)."""
    x = np.maximum(np.linalg.lstsq(a, b, rcond=None)[0], 0.0)
    step = 1.0 / max(np.linalg.norm(a, 2) ** 2, 1e-12)
    for _ in range(iterations):
        x = np.maximum(x - step * (a.T @ (a @ x - b)), 0.0)
    return x


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
    rest = _nnls(stacked[:, 1:] / scale, -stacked[:, 0])
    return np.concatenate([[1.0], rest / scale])
