"""Bounded multi-start fits of the driver MPC and of IDM to recorded car following.

Both fits minimise the same loss, the protocol's score (:mod:`human_driver_sim.evaluation`):
the mean over pairs of the gap NRMSE over re-initialised windows, averaged over the data
sets given (so that 4 long OpenACC pairs and ~70 short NGSIM pairs weigh the same).
Every parameter is bounded: the optimiser (Nelder-Mead, :func:`irl.nelder_mead`) works on
z in R^n and the parameter is ``lo + (hi - lo) * sigmoid(z)`` (weights on a log scale), so
no step can leave the box. Several starts; the best loss wins.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from human_driver_sim.driver_mpc import DriverConfig
from human_driver_sim.evaluation import IdmFollower, MpcFollower, Run, mean_gap_nrmse
from human_driver_sim.idm import FIT_BOUNDS, PARAM_NAMES, TEXTBOOK_MOTORWAY, IdmParams
from human_driver_sim.irl import nelder_mead

__all__ = ['CAUTION_BOUNDS', 'MPC_BOUNDS', 'BoundedBox', 'FitResult', 'configured', 'fit_idm',
           'fit_mpc']

MPC_BOUNDS: dict[str, tuple[float, float]] = {
    'weight_desired_speed': (1e-6, 1.0), 'weight_relative_speed': (1e-4, 10.0),
    'weight_relative_distance': (1e-5, 1.0), 'time_headway_s': (0.5, 3.0),
    'desired_standstill_gap_m': (5.0, 10.0)}
"""Bounds of the fitted driver-MPC parameters (w_a = 1 is the normalisation), SI. The
desired standstill gap starts at the safety gap the same MPC enforces (``standstill_gap_m``,
the paper's d_s = 5 m; :func:`fit_mpc` raises the floor to it if larger): the recorded data
hardly tells d_s from tau_H (docs/DRIVER_IRL.md: a fit in [1, 10] m ends at 1.14 m with a 1.6 %
lower loss and no better held-out scores), and a human who aims inside his own hard bound
would only press against it."""
CAUTION_BOUNDS: dict[str, tuple[float, float]] = {'av_extra_decel_mps2': (0.0, 3.0)}
"""Bounds of the fitted caution a_extra (fitted when the config is not ``cautious``), m/s^2:
from the expected plan's braking alone (0) to 3 m/s^2 more (with the expected plan holding
speed, the cautious driver's u_R,min = -3)."""
LOG_SCALE = frozenset({'weight_desired_speed', 'weight_relative_speed',
                       'weight_relative_distance'})


@dataclass(frozen=True)
class FitResult:
    """A fitted parameter set, its loss and how it was found."""

    params: dict[str, float]
    loss: float
    starts: list[dict[str, float]]
    start_losses: list[float]
    evaluations: int


class BoundedBox:
    """Maps z in R^n to parameters inside their bounds, and back."""

    def __init__(self, bounds: Mapping[str, tuple[float, float]],
                 log_scale: frozenset[str] = frozenset()) -> None:
        self.names = tuple(bounds)
        self._lo = np.array([math.log(bounds[n][0]) if n in log_scale else bounds[n][0]
                             for n in self.names])
        self._hi = np.array([math.log(bounds[n][1]) if n in log_scale else bounds[n][1]
                             for n in self.names])
        self._log = np.array([n in log_scale for n in self.names])

    def to_params(self, z: np.ndarray) -> dict[str, float]:
        """Parameters for z (always inside the bounds)."""
        inner = self._lo + (self._hi - self._lo) / (1.0 + np.exp(-np.asarray(z)))
        values = np.where(self._log, np.exp(inner), inner)
        return {n: float(v) for n, v in zip(self.names, values, strict=True)}

    def to_z(self, params: Mapping[str, float]) -> np.ndarray:
        """z for parameters (clipped a little inside the bounds)."""
        inner = np.array([math.log(params[n]) if log else params[n]
                          for n, log in zip(self.names, self._log, strict=True)])
        share = np.clip((inner - self._lo) / (self._hi - self._lo), 1e-3, 1 - 1e-3)
        return np.asarray(np.log(share / (1.0 - share)), dtype=float)


def _multistart(loss: Callable[[dict[str, float]], float], box: BoundedBox,
                starts: Sequence[Mapping[str, float]], iterations: int,
                progress: Callable[[int], None] | None) -> FitResult:
    calls = [0]

    def on_z(z: np.ndarray) -> float:
        calls[0] += 1
        if progress is not None:
            progress(calls[0])
        value = loss(box.to_params(z))
        return value if math.isfinite(value) else 1e9

    found = [nelder_mead(on_z, box.to_z(start), step=1.0, iterations=iterations)
             for start in starts]
    best = min(range(len(found)), key=lambda i: found[i][1])
    return FitResult(box.to_params(found[best][0]), found[best][1],
                     [dict(s) for s in starts], [f[1] for f in found], calls[0])


def dataset_loss(model_loss: Callable[[Sequence[Run]], float],
                 run_sets: Sequence[Sequence[Run]]) -> float:
    """Mean over data sets of a per-set loss."""
    return float(np.mean([model_loss(runs) for runs in run_sets]))


def configured(config: DriverConfig, params: Mapping[str, float]) -> DriverConfig:
    """The driver config with fitted parameters (w_a = 1)."""
    changes: dict[str, Any] = {'weight_acceleration': 1.0, **params}
    return dataclasses.replace(config, **changes)


def fit_mpc(config: DriverConfig, run_sets: Sequence[Sequence[Run]], *,
            starts: Sequence[Mapping[str, float]], iterations: int = 120,
            progress: Callable[[int], None] | None = None) -> FitResult:
    """Fit (w_ds, w_rs, w_rd, tau_H, d_s) of the driver MPC, bounded, from several starts;
    with ``config.cautious`` False also its caution a_extra (:data:`CAUTION_BOUNDS`).

    Args:
        config: The driver config (everything else is kept: bounds, N, dt, v_max).
        run_sets: Windows of each data set (:func:`evaluation.make_runs`).
        starts: Starting parameter sets (keys of :data:`MPC_BOUNDS`; a missing
            ``av_extra_decel_mps2`` starts at 1 m/s^2).
        iterations: Nelder-Mead iterations per start.
        progress: Called with the number of loss evaluations so far.
    """
    bounds = dict(MPC_BOUNDS)
    lo, hi = bounds['desired_standstill_gap_m']
    lo = max(lo, config.standstill_gap_m)
    bounds['desired_standstill_gap_m'] = (lo, max(hi, lo + 1.0))
    if not config.cautious:
        bounds.update(CAUTION_BOUNDS)
        starts = [{'av_extra_decel_mps2': 1.0, **start} for start in starts]
    box = BoundedBox(bounds, LOG_SCALE)

    def loss(params: dict[str, float]) -> float:
        follower = MpcFollower(configured(config, params))
        return dataset_loss(lambda runs: mean_gap_nrmse(follower, runs), run_sets)

    return _multistart(loss, box, starts, iterations, progress)


IDM_STARTS = (
    {n: float(getattr(TEXTBOOK_MOTORWAY, n)) for n in PARAM_NAMES},
    {'desired_speed_mps': 35.0, 'time_headway_s': 0.8, 'min_gap_m': 3.0,
     'max_accel_mps2': 0.6, 'comfort_decel_mps2': 2.5},
    {'desired_speed_mps': 20.0, 'time_headway_s': 1.5, 'min_gap_m': 1.5,
     'max_accel_mps2': 2.0, 'comfort_decel_mps2': 1.0},
)
"""IDM starts: the textbook motorway set and two spread ones."""


def fit_idm(run_sets: Sequence[Sequence[Run]], *,
            starts: Sequence[Mapping[str, float]] = IDM_STARTS, iterations: int = 150,
            progress: Callable[[int], None] | None = None) -> FitResult:
    """Fit IDM's five parameters inside :data:`idm.FIT_BOUNDS` from several starts."""
    box = BoundedBox(FIT_BOUNDS)

    def loss(params: dict[str, float]) -> float:
        follower = IdmFollower(IdmParams(**params))
        return dataset_loss(lambda runs: mean_gap_nrmse(follower, runs), run_sets)

    return _multistart(loss, box, starts, iterations, progress)
