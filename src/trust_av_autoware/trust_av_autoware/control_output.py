"""The planner's acceleration command as an Autoware longitudinal command, pure (no rclpy).

``autoware_control_msgs/msg/Longitudinal`` carries a velocity and an acceleration (with
``is_defined_acceleration``): :func:`longitudinal` gives the planner's acceleration and the
velocity it leads to after ``velocity_horizon_s`` from the AV's current speed (never below 0:
the planner's own speed floor ``speed_min_mps`` is 0), so a vehicle interface that follows
velocity and one that follows acceleration both do what the planner asked.

The Control's envelope, its last step before it is published: both values finite in
``float32`` (the fields' type: a float64 of 3.5e38 would be ``inf`` there), the acceleration
within +-``max_abs_accel_mps2`` (else the command is dropped), the velocity within
[0, ``input_speed_max_mps``] (clipped and counted: the AV's speed is checked against the same
range where it enters), and the steering of a copied lateral command within
+-:data:`MAX_STEERING_TIRE_ANGLE_RAD` at a rate within
+-:data:`MAX_STEERING_TIRE_RATE_RADPS`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from trust_av_autoware.lane_inputs import InputError, finite
from trust_av_common.params import check_fields, param

__all__ = ['ControlAdapterConfig', 'LongitudinalCommand', 'longitudinal']


@dataclass(frozen=True)
class ControlAdapterConfig:
    """The ``autoware_control`` adapter node (docs/operations/real-vehicle.md)."""

    base_frame_id: str = param("the AV's body frame: the planner's command must be in it "
                               '(the child_frame_id of the kinematic state)',
                               default='base_link')
    velocity_horizon_s: float = param('Longitudinal.velocity = current speed + acceleration '
                                      'x this (at least 0); also control_time - stamp',
                                      unit='s', low=0.0, high=10.0, default=0.1)
    max_abs_accel_mps2: float = param('a command whose magnitude exceeds this is dropped as '
                                      'malformed (no vehicle does it)', unit='m/s^2',
                                      low=0.0, low_inclusive=False, high=100.0, default=10.0)
    speed_timeout_s: float = param('commands are passed on only while the newest kinematic '
                                   'state (the current speed) is at most this old', unit='s',
                                   low=0.0, low_inclusive=False, high=3600.0, default=0.5)
    lateral_timeout_s: float = param("the lateral command of the stack's own controller is "
                                     'copied while it is at most this old; otherwise the '
                                     'lateral command is 0 (and the status says so)',
                                     unit='s', low=0.0, low_inclusive=False, high=3600.0,
                                     default=0.5)

    def __post_init__(self) -> None:
        check_fields(self)


MAX_STEERING_TIRE_ANGLE_RAD = 0.5 * math.pi
"""Largest |steering_tire_angle| of a lateral command passed on, rad (a tyre turned
further is not a road vehicle's)."""
MAX_STEERING_TIRE_RATE_RADPS = 10.0
"""Largest |steering_tire_rotation_rate| passed on, rad/s."""


@dataclass(frozen=True)
class LongitudinalCommand:
    """velocity (m/s) and acceleration (m/s^2) of ``Longitudinal``; ``clipped``: the
    velocity was limited to the speed range."""

    velocity_mps: float
    acceleration_mps2: float
    clipped: bool = False


FLOAT32_MAX = 3.4028234663852886e38
"""The largest finite float32 (IEEE 754 binary32): a float64 beyond it (3.5e38) rounds to
``inf`` in a float32 field."""


def float32_finite(kind: str, **values: float) -> None:
    """Raise :class:`InputError` ``kind`` naming the first value that is not finite as a
    ``float32`` (the type of Autoware's Control fields)."""
    for name, value in values.items():
        if not abs(value) <= FLOAT32_MAX:   # NaN too
            raise InputError(kind, f'{name} {value!r} is not finite as a float32')


def longitudinal(accel_mps2: float, speed_mps: float, config: ControlAdapterConfig,
                 speed_max_mps: float) -> LongitudinalCommand:
    """The command for an acceleration and the current speed, in its envelope (see the
    module docstring): the velocity at most ``speed_max_mps``.

    Raises:
        InputError: ``not_finite`` (either value, or one that overflows a float32),
            ``out_of_range`` (``|accel_mps2|`` above ``max_abs_accel_mps2``).
    """
    finite('not_finite', **{'accel.linear.x': accel_mps2, 'current speed': speed_mps})
    if abs(accel_mps2) > config.max_abs_accel_mps2:
        raise InputError('out_of_range', f'accel.linear.x {accel_mps2:g} m/s^2 beyond '
                         f'{config.max_abs_accel_mps2:g}')
    velocity = max(0.0, speed_mps + accel_mps2 * config.velocity_horizon_s)
    clipped = velocity > speed_max_mps
    velocity = min(velocity, speed_max_mps)
    float32_finite('not_finite', velocity=velocity, acceleration=accel_mps2)
    return LongitudinalCommand(velocity, accel_mps2, clipped)


def lateral_problem(angle_rad: float, rate_radps: float) -> None:
    """Check a lateral command's steering before it is copied.

    Raises:
        InputError: ``not_finite``, ``out_of_range``.
    """
    finite('not_finite', steering_tire_angle=angle_rad, steering_tire_rotation_rate=rate_radps)
    if abs(angle_rad) > MAX_STEERING_TIRE_ANGLE_RAD or \
            abs(rate_radps) > MAX_STEERING_TIRE_RATE_RADPS:
        raise InputError('out_of_range', f'steering_tire_angle {angle_rad:g} rad or its rate '
                         f'{rate_radps:g} rad/s beyond {MAX_STEERING_TIRE_ANGLE_RAD:g} rad, '
                         f'{MAX_STEERING_TIRE_RATE_RADPS:g} rad/s')
