"""Estimators of the plan the human driver expects from the AV, u_R^H (Section III-B).

Every predictor follows one interface: :meth:`Predictor.predict` gives the N expected
accelerations from what the human has seen up to the previous step, and
:meth:`Predictor.observe` adds the step just executed to the history.

A plan estimator is a component of the entry-point group ``trust_av.predictors``
(:mod:`trust_av_common.registry`): a
:class:`~trust_av_common.registry.Component` whose ``factory(planner, params)`` takes
the planner's :class:`~trust_av_planner.nmpc.PlannerConfig` (it reads ``horizon_steps``,
``dt_s`` and the acceleration bounds) and an instance of the component's ``config_type``
(None when it has none) and returns a :class:`Predictor`. Declare ``needs={'follower_state'}``
when it reads more of an :class:`Observation` than ``av_accel_mps2``: without the follower's
odometry (wall mode, no follower topic) gap, relative speed and headway are NaN, and only
estimators without that need may plan.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from trust_av_common import registry

__all__ = ['PREDICTORS', 'Observation', 'Predictor']

PREDICTORS = registry.declare('trust_av.predictors', factory_arguments=('planner', 'params'),
                              interface=('reset', 'predict', 'observe'))
"""Entry-point group of the plan estimators (the plan the human expects, u_R^H), declared
here beside their interface: ``factory(planner, params)`` returns a :class:`Predictor`."""


@dataclass(frozen=True)
class Observation:
    """What the human sees of the AV at the end of a step, eq. (6).

    Attributes:
        gap_m: d_H, human's bumper-to-bumper gap to the AV, m.
        relative_speed_mps: rs_H = v_R - v_H, m/s.
        time_headway_s: tau_H = d_H / v_H (capped), s.
        av_accel_mps2: u_R, the acceleration the AV executed, m/s^2.
    """

    gap_m: float
    relative_speed_mps: float
    time_headway_s: float
    av_accel_mps2: float


class Predictor(Protocol):
    """Interface of a plan estimator (on the model grid ``dt_s``: one observation and one
    prediction per model step).

    An estimator that uses more than the last observation may say how many with an
    ``history_steps`` attribute (int; default 1): at a control period shorter than ``dt_s``
    it is then fed that many 1 s samples (:mod:`trust_av_planner.predictors.sampling`).
    """

    def reset(self) -> None:
        """Forget the history."""

    def predict(self) -> np.ndarray:
        """Expected AV plan u_R^H over the horizon: ``horizon_steps`` accelerations, m/s^2,
        finite and within the AV's acceleration bounds."""

    def observe(self, observation: Observation) -> None:
        """Record the step just executed."""
