"""The AV's per-step decision, shared by the in-process loop and the ``planner`` node.

:class:`AvPlanner` turns odometry (what a real vehicle publishes) into a plan: it updates
the plan estimator with what the human saw after the previous step, predicts the plan the
human expects, and solves the trust-aware NMPC.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from trust_av_planner.nmpc import PlannerConfig, PlanResult, TrustAwareNmpc
from trust_av_planner.predictors import Observation, Predictor
from trust_av_planner.predictors.ca import ConstantAccelerationPredictor
from trust_av_planner.predictors.gru import GruPredictor, resolve_model
from trust_monitor.common.kinematics import VehicleState, gap_m
from trust_monitor.trust_model import TrustConfig


def make_predictor(config: PlannerConfig) -> Predictor:
    """The plan estimator named by the ``predictor`` parameter."""
    if config.predictor == 'ca':
        return ConstantAccelerationPredictor(config.horizon_steps, config.accel_min_mps2,
                                             config.accel_max_mps2)
    if config.predictor == 'gru':
        return GruPredictor.from_file(resolve_model(config.gru_model), config.horizon_steps,
                                      config.dt_s, config.accel_min_mps2, config.accel_max_mps2)
    raise ValueError(f'unknown predictor {config.predictor!r}')


def observe(av: VehicleState, human: VehicleState, av_accel_mps2: float, length_m: float,
            headway_cap_s: float) -> Observation:
    """What the human sees of the AV, eq. (6): gap, relative speed, headway, AV acceleration."""
    gap = gap_m(av, human, length_m)
    headway = gap / human.speed_mps if human.speed_mps * headway_cap_s > gap else headway_cap_s
    return Observation(gap_m=gap, relative_speed_mps=av.speed_mps - human.speed_mps,
                       time_headway_s=headway, av_accel_mps2=av_accel_mps2)


@dataclass(frozen=True)
class PlannerOutput:
    """One planning step: the NMPC's result, the expected plan and the gap it planned from."""

    result: PlanResult
    expected_mps2: np.ndarray
    gap_m: float


class AvPlanner:
    """Predictor + trust-aware NMPC with the state they carry between steps."""

    def __init__(self, config: PlannerConfig, trust: TrustConfig, vehicle_length_m: float,
                 predictor: Predictor | None = None) -> None:
        self.config = config
        self.vehicle_length_m = vehicle_length_m
        self.nmpc = TrustAwareNmpc(config, trust)
        self.predictor = predictor if predictor is not None else make_predictor(config)
        self._last_accel: float | None = None

    def step(self, traffic: VehicleState, preview_mps: np.ndarray, av: VehicleState,
             human: VehicleState | None, trust: float) -> PlannerOutput:
        """Plan from the vehicles' odometry at the start of a step.

        Args:
            traffic: preceding vehicle's odometry.
            preview_mps: its speed over the horizon (N values; the first is its speed now).
            av: the AV's odometry.
            human: the human follower's odometry; None when it is not known (wall mode
                without a follower topic): the plan estimator then observes only the AV's
                acceleration (gap, relative speed and headway NaN), which is all the CA
                predictor uses; other predictors need the follower.
            trust: the monitor's trust estimate T(t).

        Raises:
            ValueError: ``human`` is None and the predictor is not the CA predictor.
        """
        if human is None and not isinstance(self.predictor, ConstantAccelerationPredictor):
            raise ValueError('planning without the human follower state needs predictor ca')
        if self._last_accel is not None and human is None:
            self.predictor.observe(Observation(gap_m=math.nan, relative_speed_mps=math.nan,
                                               time_headway_s=math.nan,
                                               av_accel_mps2=self._last_accel))
        elif self._last_accel is not None and human is not None:
            self.predictor.observe(observe(av, human, self._last_accel, self.vehicle_length_m,
                                           self.config.time_headway_cap_s))
        expected = self.predictor.predict()
        gap = gap_m(traffic, av, self.vehicle_length_m)
        result = self.nmpc.step(gap, av.speed_mps, np.asarray(preview_mps, dtype=float),
                                 expected, trust)
        self._last_accel = float(result.plan_mps2[0])
        return PlannerOutput(result, expected, gap)
