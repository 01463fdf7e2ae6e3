"""Intelligent Driver Model (Treiber, Hennecke & Helbing 2000), the car-following baseline.

Two fixed parameter sets are named here: :data:`TEXTBOOK_MOTORWAY` and the physical
bounds of a fit, :data:`FIT_BOUNDS`. The fit itself is in :mod:`human_driver_sim.fitting`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from human_driver_sim.driver_mpc import DriverConfig, DriverResult
from trust_av_common.params import check_fields, param
from trust_av_common.registry import Component

__all__ = ['COMPONENT', 'FIT_BOUNDS', 'PARAM_NAMES', 'TEXTBOOK_MOTORWAY', 'IdmConfig',
           'IdmFollower', 'IdmParams', 'idm_accel', 'idm_accel_array']


@dataclass(frozen=True)
class IdmParams:
    """IDM parameters (SI units); validated on construction."""

    desired_speed_mps: float = 33.0
    time_headway_s: float = 1.5
    min_gap_m: float = 2.0
    max_accel_mps2: float = 1.0
    comfort_decel_mps2: float = 1.5

    def __post_init__(self) -> None:
        for name in ('desired_speed_mps', 'time_headway_s', 'max_accel_mps2',
                     'comfort_decel_mps2'):
            if not getattr(self, name) > 0.0:
                raise ValueError(f'IdmParams.{name} must be positive')
        if self.min_gap_m < 0.0:
            raise ValueError('IdmParams.min_gap_m must be non-negative')


TEXTBOOK_MOTORWAY = IdmParams(desired_speed_mps=120.0 / 3.6, time_headway_s=1.0, min_gap_m=2.0,
                              max_accel_mps2=1.0, comfort_decel_mps2=1.5)
"""IDM for motorway traffic as given by Treiber & Kesting, *Traffic Flow Dynamics* (Springer
2013), Table 11.2: v0 = 120 km/h, T = 1.0 s, s0 = 2 m, a = 1.0 m/s^2, b = 1.5 m/s^2, delta 4."""

FIT_BOUNDS = {'desired_speed_mps': (10.0, 45.0), 'time_headway_s': (0.5, 3.0),
              'min_gap_m': (1.0, 8.0), 'max_accel_mps2': (0.3, 4.0),
              'comfort_decel_mps2': (0.5, 4.0)}
"""Physical bounds of a fitted IDM (b <= 4 m/s^2, s0 >= 1 m, T >= 0.5 s), SI."""
PARAM_NAMES = tuple(FIT_BOUNDS)


def idm_accel_array(params: IdmParams, gap_m: np.ndarray, speed_mps: np.ndarray,
                    leader_speed_mps: np.ndarray) -> np.ndarray:
    """IDM accelerations for many states at once, m/s^2 (the gap floored at 0.1 m)."""
    speed = np.asarray(speed_mps, dtype=float)
    star = params.min_gap_m + np.maximum(
        0.0, speed * params.time_headway_s + speed * (speed - leader_speed_mps)
        / (2.0 * np.sqrt(params.max_accel_mps2 * params.comfort_decel_mps2)))
    ratio = (speed / params.desired_speed_mps) ** 4
    return np.asarray(params.max_accel_mps2
                      * (1.0 - ratio - (star / np.maximum(gap_m, 0.1)) ** 2), dtype=float)


def idm_accel(params: IdmParams, gap_m: float, speed_mps: float, leader_speed_mps: float) -> float:
    """IDM acceleration, m/s^2."""
    star = params.min_gap_m + max(0.0, speed_mps * params.time_headway_s + speed_mps
                                  * (speed_mps - leader_speed_mps)
                                  / (2.0 * np.sqrt(params.max_accel_mps2
                                                   * params.comfort_decel_mps2)))
    ratio = (speed_mps / params.desired_speed_mps) ** 4
    return float(params.max_accel_mps2 * (1.0 - ratio - (star / max(gap_m, 0.1)) ** 2))


_REASON = 'the follower model is built at start-up'


@dataclass(frozen=True)
class IdmConfig:
    """Parameters of the IDM follower (``driver_model: idm``), in the ``human_driver``
    section; defaults :data:`TEXTBOOK_MOTORWAY`, ranges :data:`FIT_BOUNDS`."""

    idm_desired_speed_mps: float = param('IDM desired speed v0', unit='m/s',
                                         low=FIT_BOUNDS['desired_speed_mps'][0],
                                         high=FIT_BOUNDS['desired_speed_mps'][1],
                                         default=TEXTBOOK_MOTORWAY.desired_speed_mps,
                                         reason=_REASON)
    idm_time_headway_s: float = param('IDM time headway T', unit='s',
                                      low=FIT_BOUNDS['time_headway_s'][0],
                                      high=FIT_BOUNDS['time_headway_s'][1],
                                      default=TEXTBOOK_MOTORWAY.time_headway_s, reason=_REASON)
    idm_min_gap_m: float = param('IDM standstill gap s0', unit='m',
                                 low=FIT_BOUNDS['min_gap_m'][0], high=FIT_BOUNDS['min_gap_m'][1],
                                 default=TEXTBOOK_MOTORWAY.min_gap_m, reason=_REASON)
    idm_max_accel_mps2: float = param('IDM maximum acceleration a', unit='m/s^2',
                                      low=FIT_BOUNDS['max_accel_mps2'][0],
                                      high=FIT_BOUNDS['max_accel_mps2'][1],
                                      default=TEXTBOOK_MOTORWAY.max_accel_mps2, reason=_REASON)
    idm_comfort_decel_mps2: float = param('IDM comfortable deceleration b', unit='m/s^2',
                                          low=FIT_BOUNDS['comfort_decel_mps2'][0],
                                          high=FIT_BOUNDS['comfort_decel_mps2'][1],
                                          default=TEXTBOOK_MOTORWAY.comfort_decel_mps2,
                                          reason=_REASON)

    def __post_init__(self) -> None:
        check_fields(self)

    @property
    def params(self) -> IdmParams:
        """As :class:`IdmParams`."""
        return IdmParams(self.idm_desired_speed_mps, self.idm_time_headway_s,
                         self.idm_min_gap_m, self.idm_max_accel_mps2,
                         self.idm_comfort_decel_mps2)


class IdmFollower:
    """The IDM as a follower model: at each of the N model steps the IDM acceleration
    against the AV predicted with the plan the human expects, clipped to the human's
    acceleration bounds and to what keeps its speed within ``[speed_min_mps,
    speed_max_mps]``. The first value is applied; it has no state between steps.

    Args:
        config: the ``human_driver`` section (step, horizon, bounds).
        idm: the IDM's parameters.
    """

    def __init__(self, config: DriverConfig, idm: IdmConfig) -> None:
        self.config = config
        self.params = idm.params

    def reset(self) -> None:
        """Nothing to forget."""

    def step(self, gap_m: float, speed_mps: float, av_speed_mps: float,
             expected_mps2: np.ndarray) -> DriverResult:
        """The IDM plan over the horizon (status ``idm``; never a fallback).

        Args:
            gap_m: gap from the human's front bumper to the AV's rear bumper, m.
            speed_mps: human's speed, m/s.
            av_speed_mps: AV's current speed, m/s.
            expected_mps2: the AV plan the human expects, N values, m/s^2.
        """
        start = time.perf_counter()
        c, dt = self.config, self.config.dt_s
        gap, speed, av_speed = float(gap_m), float(speed_mps), float(av_speed_mps)
        plan = np.empty(c.horizon_steps)
        for k in range(c.horizon_steps):
            accel = idm_accel(self.params, gap, speed, av_speed)
            low = max(c.accel_min_mps2, (c.speed_min_mps - speed) / dt)
            high = min(c.accel_max_mps2, (c.speed_max_mps - speed) / dt)
            accel = max(low, min(accel, high))
            plan[k] = accel
            av_accel = max(float(expected_mps2[k]), -av_speed / dt)
            gap += (av_speed - speed) * dt + 0.5 * (av_accel - accel) * dt * dt
            speed += accel * dt
            av_speed += av_accel * dt
        return DriverResult(plan, 'idm', True, 0, time.perf_counter() - start)


def build(config: DriverConfig, params: IdmConfig) -> IdmFollower:
    """The IDM follower with ``params`` on the ``human_driver`` section's grid and bounds."""
    return IdmFollower(config, params)


COMPONENT = Component(
    name='idm', factory=build, config_type=IdmConfig,
    description='Intelligent Driver Model (Treiber et al. 2000) against the expected AV plan')
"""Registered as ``idm`` in ``trust_av.drivers`` (human_driver_sim's setup.py)."""
