"""Intelligent Driver Model (Treiber, Hennecke & Helbing 2000), the car-following baseline."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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


def idm_accel(params: IdmParams, gap_m: float, speed_mps: float, leader_speed_mps: float) -> float:
    """IDM acceleration, m/s^2."""
    star = params.min_gap_m + max(0.0, speed_mps * params.time_headway_s + speed_mps
                                  * (speed_mps - leader_speed_mps)
                                  / (2.0 * np.sqrt(params.max_accel_mps2
                                                   * params.comfort_decel_mps2)))
    ratio = (speed_mps / params.desired_speed_mps) ** 4
    return float(params.max_accel_mps2 * (1.0 - ratio - (star / max(gap_m, 0.1)) ** 2))


def replay(params: IdmParams, leader_speed_mps: np.ndarray, gap0_m: float, speed0_mps: float,
           dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Open-loop replay of an IDM follower against a recorded leader.

    Returns:
        (gap_m, speed_mps) per sample, same length as ``leader_speed_mps``.
    """
    count = len(leader_speed_mps)
    gap = np.empty(count)
    speed = np.empty(count)
    gap[0], speed[0] = gap0_m, speed0_mps
    for k in range(count - 1):
        accel = idm_accel(params, gap[k], speed[k], float(leader_speed_mps[k]))
        new_speed = max(0.0, speed[k] + accel * dt_s)
        travelled = 0.5 * (speed[k] + new_speed) * dt_s
        lead = 0.5 * (leader_speed_mps[k] + leader_speed_mps[k + 1]) * dt_s
        gap[k + 1] = gap[k] + lead - travelled
        speed[k + 1] = new_speed
    return gap, speed
