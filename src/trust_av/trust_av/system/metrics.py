"""What a closed-loop run produced: one :class:`StepRecord` per control step, and the
:class:`Metrics` that summarise a run (docs/concepts/reading-the-paper.md). Shared by the
in-process loop, the graph's recordings (read back into the same records) and the study."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from trust_av_common.kinematics import Collision, collision

__all__ = ['Metrics', 'StepRecord', 'compute_metrics', 'expectation_errors',
           'explicability_by_age', 'first_collision', 'step_change_rms_mps2',
           'ticks_per_model_step']


@dataclass(frozen=True)
class StepRecord:
    """Everything that happened in one control step (states at the step's start)."""

    t_s: float
    traffic_position_m: float
    traffic_speed_mps: float
    av_position_m: float
    av_speed_mps: float
    av_gap_m: float
    human_position_m: float
    human_speed_mps: float
    human_gap_m: float
    av_accel_mps2: float
    human_accel_mps2: float
    av_plan_mps2: tuple[float, ...]
    expected_plan_mps2: tuple[float, ...]
    human_plan_mps2: tuple[float, ...]
    explicability: float
    performance: float
    trust: float
    explicability_max: float
    solver_status: str
    solver_success: bool
    solver_iterations: int
    solve_time_s: float
    driver_status: str
    driver_success: bool
    driver_solve_time_s: float


@dataclass(frozen=True)
class Metrics:
    """Summary of a run: final trust, mean E, prediction RMSE, gaps, fallbacks."""

    steps: int
    final_trust: float
    mean_explicability: float
    rmse_mps2: float
    min_av_gap_m: float
    min_human_gap_m: float
    fallback_steps: int
    driver_fallback_steps: int
    unsafe_steps: int = 0
    collision: Collision | None = None
    """The first step whose gaps show a collision; the figures above end with it."""


def first_collision(records: list[StepRecord]) -> Collision | None:
    """The first collision the records show (a gap at or below 0 m,
    :func:`~trust_av_common.kinematics.collision`), or None."""
    for index, record in enumerate(records):
        found = collision(index, record.t_s, record.av_gap_m, record.human_gap_m)
        if found is not None:
            return found
    return None


def compute_metrics(records: list[StepRecord], min_safe_gap_m: float,
                    plan_step_s: float | None = None) -> Metrics:
    """The run's metrics (docs/concepts/reading-the-paper.md, "The RMSE column"); RMSE
    compares each value of u_R^H(t) with the acceleration the AV executed at its time
    (:func:`expectation_errors`).

    ``unsafe_steps`` counts steps where either gap is below ``min_safe_gap_m`` (a collision
    margin, ``standstill_gap_m - safety_gap_margin_m``); every shipped run must have none.
    ``plan_step_s``: the step of the plans' grid when it is not the control period
    (``prediction_grid: model_step`` at a faster rate); None = the control period.
    A run that collided (:func:`first_collision`) is summarised up to and including the
    collision step (records after it, if given any, are not a car-following run any more),
    and ``collision`` names it.

    Raises:
        ValueError: no records (there is nothing to summarise).
    """
    if not records:
        raise ValueError('no steps to summarise')
    crash = first_collision(records)
    if crash is not None:
        records = records[:crash.step + 1]
    errors = expectation_errors(records, plan_step_s)
    return Metrics(
        steps=len(records),
        final_trust=records[-1].trust,
        mean_explicability=float(np.mean([r.explicability for r in records])),
        rmse_mps2=float(math.sqrt(np.mean(np.square(errors)))),
        min_av_gap_m=min(r.av_gap_m for r in records),
        min_human_gap_m=min(r.human_gap_m for r in records),
        fallback_steps=sum(not r.solver_success for r in records),
        driver_fallback_steps=sum(not r.driver_success for r in records),
        unsafe_steps=sum(min(r.av_gap_m, r.human_gap_m) < min_safe_gap_m for r in records),
        collision=crash,
    )


def expectation_errors(records: list[StepRecord],
                       plan_step_s: float | None = None) -> np.ndarray:
    """u_R^H(t)[k] minus the acceleration the AV executed at t + k * plan_step_s, for every
    step t and every k whose time is within the run, m/s^2.

    The executed acceleration at a time is the command of the control step then (held over
    its period). ``plan_step_s`` must be a whole number of control periods; None = the
    control period (value k is compared with the command k steps later).

    Raises:
        ValueError: ``plan_step_s`` is not a whole number of control periods.
    """
    executed = np.array([r.av_accel_mps2 for r in records])
    stride = 1
    if plan_step_s is not None and len(records) > 1:
        stride = ticks_per_model_step(records[1].t_s - records[0].t_s, plan_step_s)
    errors = [predicted - executed[t + k * stride]
              for t, r in enumerate(records)
              for k, predicted in enumerate(r.expected_plan_mps2)
              if t + k * stride < executed.size]
    return np.asarray(errors, dtype=float)


def ticks_per_model_step(period_s: float, model_step_s: float) -> int:
    """How many control periods make one model step (10 at 10 Hz with the paper's 1 s).

    Raises:
        ValueError: the model step is not a whole number of periods.
    """
    ticks = round(model_step_s / period_s)
    if ticks < 1 or abs(ticks * period_s - model_step_s) > 1e-9 * model_step_s:
        raise ValueError(f'the model step {model_step_s:g} s is not a whole number of '
                         f'{period_s:g} s periods')
    return ticks


def step_change_rms_mps2(records: list[StepRecord], ticks: int) -> float:
    """RMS change of the AV's executed acceleration from one model step to the next, each
    step's value its mean over the step's ``ticks`` control periods, m/s^2 (at the model
    rate, ``ticks`` = 1, the change between consecutive commands). How much the AV's
    behaviour moves between 1 s samples: what a constant-acceleration expectation misses."""
    executed = np.array([r.av_accel_mps2 for r in records])
    whole = executed[:executed.size - executed.size % ticks].reshape(-1, ticks).mean(axis=1)
    if whole.size < 2:
        raise ValueError('need at least two model steps')
    return float(math.sqrt(np.mean(np.square(np.diff(whole)))))


def explicability_by_age(records: list[StepRecord], ticks: int) -> np.ndarray:
    """Mean E by the age of the expectation: entry j is the mean over the control steps j
    periods after a whole model step of the run (when the 1 s estimator's samples were
    taken, :class:`~trust_av_planner.predictors.sampling.ModelGridPredictor`), j = 0..ticks-1.
    """
    scores = np.array([r.explicability for r in records])
    if scores.size < ticks:
        raise ValueError(f'need at least {ticks} steps')
    out: np.ndarray = np.array([scores[j::ticks].mean() for j in range(ticks)])
    return out
