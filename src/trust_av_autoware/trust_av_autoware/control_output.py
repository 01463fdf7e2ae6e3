"""The planner's acceleration command as an Autoware longitudinal command, pure (no rclpy).

``autoware_control_msgs/msg/Longitudinal`` carries a velocity and an acceleration (with
``is_defined_acceleration``): :func:`longitudinal` gives the planner's acceleration and the
velocity it leads to after ``velocity_horizon_s`` from the AV's current speed (never below 0:
the planner's own speed floor ``speed_min_mps`` is 0), so a vehicle interface that follows
velocity and one that follows acceleration both do what the planner asked.
"""

from __future__ import annotations

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


@dataclass(frozen=True)
class LongitudinalCommand:
    """velocity (m/s) and acceleration (m/s^2) of ``Longitudinal``."""

    velocity_mps: float
    acceleration_mps2: float


def longitudinal(accel_mps2: float, speed_mps: float,
                 config: ControlAdapterConfig) -> LongitudinalCommand:
    """The command for an acceleration and the current speed.

    Raises:
        InputError: ``not_finite`` (either value), ``out_of_range`` (``|accel_mps2|`` above
            ``max_abs_accel_mps2``).
    """
    finite('not_finite', **{'accel.linear.x': accel_mps2, 'current speed': speed_mps})
    if abs(accel_mps2) > config.max_abs_accel_mps2:
        raise InputError('out_of_range', f'accel.linear.x {accel_mps2:g} m/s^2 beyond '
                         f'{config.max_abs_accel_mps2:g}')
    return LongitudinalCommand(max(0.0, speed_mps + accel_mps2 * config.velocity_horizon_s),
                               accel_mps2)
