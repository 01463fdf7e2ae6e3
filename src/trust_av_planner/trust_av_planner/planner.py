"""The AV's per-step decision, shared by the in-process loop and the ``planner`` node.

:class:`AvPlanner` turns odometry (what a real vehicle publishes) into a plan: it updates
the plan estimator with what the human saw after the previous step, predicts the plan the
human expects, takes or builds the lead's preview (:mod:`trust_av_planner.preview`), and
solves the trust-aware NMPC. At any control period: the NMPC predicts on its grid
(:func:`~trust_av_planner.nmpc.prediction_grid`), the estimator sees 1 s samples
(:mod:`trust_av_planner.predictors.sampling`).
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from trust_av_common import registry
from trust_av_common.component_checks import PASSING, call, check_plan, raised
from trust_av_common.kinematics import VehicleState, gap_m
from trust_av_planner.nmpc import PlannerConfig, TrustAwareNmpc
from trust_av_planner.perturbations import Perturbation, stopping_cap_mps2
from trust_av_planner.plan_result import PlanResult
from trust_av_planner.predictors import PREDICTORS, Observation, Predictor
from trust_av_planner.predictors.sampling import ModelGridPredictor
from trust_av_planner.preview import LeadPreview, hold_on_grid
from trust_monitor.model_interface import TrustModel
from trust_monitor.paper_trust import TrustConfig

__all__ = ['AvPlanner', 'CheckedPredictor', 'make_predictor', 'needs_follower_state', 'observe']


def make_predictor(config: PlannerConfig, params: Any = None) -> Predictor:
    """The plan estimator registered under the ``predictor`` parameter's name.

    Args:
        config: the planner's parameters (horizon, step, acceleration bounds).
        params: the estimator's own parameters (its ``config_type``; None: its defaults).

    Raises:
        RegistryError: the name is not registered, its entry point is broken, or its
            factory fails or returns no predictor.
    """
    component = registry.get(PREDICTORS, config.predictor)
    predictor: Predictor = registry.build(PREDICTORS, component, config,
                                          registry.config_of(component, params))
    return predictor


class CheckedPredictor:
    """A plan estimator whose every call is checked where it enters the loop
    (:mod:`trust_av_common.component_checks`): a prediction must be ``horizon_steps``
    finite accelerations within the planner's bounds; anything the estimator raises names
    it. :class:`AvPlanner` (the in-process loop's and the ``planner`` node's) wraps its
    estimator in one.

    Args:
        inner: the estimator.
        config: the planner's parameters (its ``predictor`` names the estimator).
    """

    def __init__(self, inner: Predictor, config: PlannerConfig) -> None:
        self.inner = inner
        self.config = config
        self.steps_done = 0
        self.history_steps = int(getattr(inner, 'history_steps', 1))

    def reset(self) -> None:
        """Forget the history (the step count goes on: at a control period shorter than
        ``dt_s`` the sampler resets the estimator before every prediction)."""
        call(PREDICTORS, self.config.predictor, self.steps_done, 'reset()',
             self.inner.reset)

    def observe(self, observation: Observation) -> None:
        """Record the step just executed."""
        try:
            self.inner.observe(observation)
        except PASSING:
            raise
        except BaseException as err:
            raise raised(PREDICTORS, self.config.predictor, self.steps_done,
                         'observe()', err) from err

    def predict(self) -> np.ndarray:
        """The estimator's prediction, checked (a float array).

        Raises:
            ComponentError: it raised, or the prediction breaks the interface.
        """
        c, k = self.config, self.steps_done
        try:
            value = self.inner.predict()
        except PASSING:
            raise
        except BaseException as err:
            raise raised(PREDICTORS, c.predictor, k, 'predict()', err) from err
        plan = check_plan(value, group=PREDICTORS, name=c.predictor, step=k,
                          steps=c.horizon_steps, low=c.accel_min_mps2, high=c.accel_max_mps2)
        self.steps_done += 1
        return plan


def needs_follower_state(config: PlannerConfig) -> bool:
    """Whether the configured plan estimator declares that it needs the follower's state."""
    return registry.FOLLOWER_STATE in registry.get(PREDICTORS, config.predictor).needs


def observe(av: VehicleState, human: VehicleState, av_accel_mps2: float, length_m: float,
            headway_cap_s: float) -> Observation:
    """What the human sees of the AV, eq. (6): gap, relative speed, headway, AV acceleration.

    The time headway d_H / v_H is capped at ``headway_cap_s`` (a stopped or slow human); a
    stopped human at a gap at or below 0 m (a collision) has headway 0 s, never a division
    by a zero speed.
    """
    gap = gap_m(av, human, length_m)
    if gap <= 0.0:
        headway = 0.0            # touching or overlapping the AV: no headway (no division)
    else:
        headway = gap / human.speed_mps if human.speed_mps * headway_cap_s > gap \
            else headway_cap_s
    return Observation(gap_m=gap, relative_speed_mps=av.speed_mps - human.speed_mps,
                       time_headway_s=headway, av_accel_mps2=av_accel_mps2)


@dataclass(frozen=True)
class PlannerOutput:
    """One planning step.

    Attributes:
        result: the NMPC's result (its plan on the prediction grid).
        expected_mps2: the plan the human expects, held onto the prediction grid.
        expected_model_mps2: the same plan on the model grid (``dt_s``), as the estimator
            gave it (what the human driver model receives).
        preview_mps: the lead's speed on the prediction grid the NMPC used.
        gap_m: the gap it planned from, m.
    """

    result: PlanResult
    expected_mps2: np.ndarray
    expected_model_mps2: np.ndarray
    preview_mps: np.ndarray
    gap_m: float


class AvPlanner:
    """Predictor + trust-aware NMPC with the state they carry between steps.

    Args:
        config: the planner's parameters.
        trust: the trust model.
        vehicle_length_m: odometry position to bumper-to-bumper gap, m.
        predictor: the plan estimator on the model grid (default: :func:`make_predictor`).
        predictor_params: the registered estimator's parameters (its ``config_type``;
            None: its defaults), when ``predictor`` is None.
        period_s: the control period, s (None = ``dt_s``, the paper's loop). At another
            period the NMPC predicts on :func:`~trust_av_planner.nmpc.prediction_grid` and
            the estimator is fed 1 s samples (:class:`ModelGridPredictor`).
        cpu_budget: the NMPC's CPU budget applies (a loop against the wall clock;
            :class:`TrustAwareNmpc`).
    """

    def __init__(self, config: PlannerConfig, trust: TrustConfig, vehicle_length_m: float,
                 predictor: Predictor | None = None, period_s: float | None = None, *,
                 cpu_budget: bool = False, predictor_params: Any = None,
                 trust_model: TrustModel | None = None) -> None:
        self.config = config
        self.vehicle_length_m = vehicle_length_m
        self.period_s = config.dt_s if period_s is None else period_s
        self.nmpc = TrustAwareNmpc(config, trust, self.period_s, cpu_budget=cpu_budget,
                                   trust_model=trust_model)
        self.predictor = CheckedPredictor(predictor if predictor is not None
                                          else make_predictor(config, predictor_params), config)
        self.needs_follower = needs_follower_state(config)
        self.same_grid = abs(self.period_s - config.dt_s) <= 1e-12 * config.dt_s
        history = self.predictor.history_steps
        self.sampler = None if self.same_grid else ModelGridPredictor(
            self.predictor, config.dt_s, history)
        self.lead = (None if config.lead_preview == 'recorded'
                     else LeadPreview(config.lead_preview, config.lead_accel_window_s))
        self._last_accel: float | None = None
        self._last_t_s: float | None = None
        self._t_s = 0.0
        self.perturbation = Perturbation(config.perturbation, config.perturbation_seed,
                                         config.accel_min_mps2)
        self._first_t_s: float | None = None

    @property
    def grid(self) -> tuple[float, int]:
        """The NMPC's prediction grid: (step in s, steps)."""
        return self.nmpc.grid_step_s, self.nmpc.steps

    def retune(self, config: PlannerConfig) -> None:
        """New values of the run-time parameters from the next step on (see
        :meth:`TrustAwareNmpc.retune`)."""
        self.nmpc.retune(config)
        self.config = self.predictor.config = config

    def step(self, traffic: VehicleState, preview_mps: np.ndarray | None, av: VehicleState,
             human: VehicleState | None, trust: Any, t_s: float | None = None) -> PlannerOutput:
        """Plan from the vehicles' odometry at the start of a step.

        Args:
            traffic: preceding vehicle's odometry.
            preview_mps: its speed on the prediction grid (:attr:`grid`; the first value is
                its speed now) when ``lead_preview`` is ``recorded``; otherwise None and the
                preview is built from ``traffic``.
            av: the AV's odometry.
            human: the human follower's odometry; None when it is not known (wall mode
                without a follower topic): the plan estimator then observes only the AV's
                acceleration (gap, relative speed and headway NaN), which is enough for an
                estimator that does not declare the ``follower_state`` need.
            trust: the monitor's trust state (for ``paper``: the estimate T(t)).
            t_s: time of this step, s (default: one control period after the previous).

        Raises:
            ValueError: ``human`` is None and the plan estimator needs the follower's state;
                a recorded preview is missing, or given while the planner builds its own.
        """
        t_s = self._t_s if t_s is None else t_s
        if human is None and self.needs_follower:
            raise ValueError(f'predictor {self.config.predictor} needs the human follower '
                             "state (it declares the need 'follower_state')")
        expected_model, age_s = self.expect(av, human, t_s)
        step_s, steps = self.grid
        expected = hold_on_grid(expected_model, self.config.dt_s, step_s, steps, age_s)
        preview = self.lead_preview(traffic, preview_mps, t_s)
        gap = gap_m(traffic, av, self.vehicle_length_m)
        if self._first_t_s is None:
            self._first_t_s = t_s
        since_s = t_s - self._first_t_s
        # a study condition (perturbations.py): the NMPC plans from a shorter gap after an
        # unannounced headway change, and its command is capped during a brake/hesitation
        planned_gap = gap - self.perturbation.headway_s(since_s) * av.speed_mps
        result = self.nmpc.step(planned_gap, av.speed_mps, preview, expected, trust)
        if self.perturbation.active:
            commanded = self.perturbation.apply(result.plan_mps2, since_s, step_s)
            # ... and never left unable to brake to the lead's stop (perturbations.py)
            c = self.config
            lead_next = float(np.interp(self.period_s, step_s * np.arange(steps), preview))
            cap = stopping_cap_mps2(av.speed_mps, gap, traffic.speed_mps, lead_next,
                                    self.period_s, -c.accel_min_mps2, c.standstill_gap_m)
            commanded[0] = max(min(commanded[0], cap), c.accel_min_mps2)
            if not np.array_equal(commanded, result.plan_mps2):
                result = dataclasses.replace(result, plan_mps2=commanded)
        self.commanded(float(result.plan_mps2[0]), t_s)
        return PlannerOutput(result, expected, expected_model, preview, gap)

    def warm_up(self, solves: int, trust_state: object) -> list[float]:
        """Solve the NMPC ``solves`` times on a steady car-following state (mid speed, at
        the headway), then forget the warm start: the first-use costs leave the first
        real step. Only the NMPC is stepped: the plan estimator sees nothing.

        Args:
            solves: solves to make.
            trust_state: the trust model's initial state (a T below T_min is raised above
                it: the NMPC would fall back without a solve).

        Returns:
            Each solve's wall time, s.
        """
        nmpc, c = self.nmpc, self.config
        speed = 0.5 * (c.speed_min_mps + c.speed_max_mps)
        gap = c.standstill_gap_m + c.time_headway_s * speed
        if isinstance(trust_state, float):
            trust_state = max(trust_state, c.trust_min + 1.0)
        times = []
        for _ in range(solves):
            start = time.perf_counter()
            nmpc.step(gap, speed, np.full(nmpc.steps, speed), np.zeros(nmpc.steps), trust_state)
            times.append(time.perf_counter() - start)
        nmpc.reset()
        return times

    def hold(self, accel_mps2: float, av: VehicleState | None, human: VehicleState | None,
             t_s: float) -> tuple[np.ndarray, np.ndarray]:
        """A step without the NMPC (an input is stale): ``accel_mps2`` is commanded; the
        estimator still observes what it can (nothing without the AV's odometry, nothing
        without the follower's when it needs the follower's state).

        Returns:
            The plan (``accel_mps2`` over the prediction grid) and the expected plan on the
            prediction grid.
        """
        usable = av is not None and (human is not None or not self.needs_follower)
        expected_model, age_s = self.expect(av if usable else None, human, t_s)
        step_s, steps = self.grid
        self.commanded(accel_mps2, t_s)
        return (np.full(steps, accel_mps2),
                hold_on_grid(expected_model, self.config.dt_s, step_s, steps, age_s))

    def expect(self, av: VehicleState | None, human: VehicleState | None,
               t_s: float) -> tuple[np.ndarray, float]:
        """The plan the human expects (model grid), after observing the last step (not when
        ``av`` is None), and how long ago that plan began (s; 0 at the paper's period)."""
        applied = self._last_accel
        if applied is not None and av is not None and (self._last_t_s is None
                                                       or t_s > self._last_t_s):
            if human is None:
                seen = Observation(gap_m=math.nan, relative_speed_mps=math.nan,
                                   time_headway_s=math.nan, av_accel_mps2=applied)
            else:
                seen = observe(av, human, applied, self.vehicle_length_m,
                               self.config.time_headway_cap_s)
            if self.sampler is None:
                self.predictor.observe(seen)
            else:
                last = t_s - self.period_s if self._last_t_s is None else self._last_t_s
                self.sampler.observe(seen, t_s, t_s - last)
        if self.sampler is None:
            return self.predictor.predict(), 0.0
        return self.sampler.predict(t_s)

    def lead_preview(self, traffic: VehicleState, preview_mps: np.ndarray | None,
                     t_s: float) -> np.ndarray:
        """The lead's speed on the prediction grid: the recorded preview, or one built from
        its odometry (``lead_preview``)."""
        if self.lead is None:
            if preview_mps is None:
                raise ValueError('lead_preview is recorded but no preview was given')
            return np.asarray(preview_mps, dtype=float)
        if preview_mps is not None:
            raise ValueError(f'lead_preview is {self.config.lead_preview}: the planner builds '
                             'the preview, none may be given')
        self.lead.observe(t_s, traffic.speed_mps)
        return self.lead.preview(*self.grid)

    def commanded(self, accel_mps2: float, t_s: float) -> None:
        """Record the command of the step at ``t_s`` (what the estimator sees applied next)."""
        self._last_accel = accel_mps2
        self._last_t_s = t_s
        self._t_s = t_s + self.period_s
