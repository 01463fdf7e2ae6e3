"""The participant's car, pure part: what acceleration is applied and how the car moves.

A person's pedal arrives as acceleration commands (m/s^2). The follower plant applies the
newest command as soon as it arrives. When commands stop (tab closed, connection lost, page
frozen) the car reacts in two documented phases, as a driver-assistance fallback would:

1. **hold**: for ``input_timeout_s`` after the last command the last command is kept (a
   late sample is normal jitter, not a lost participant);
2. **coast**: then for ``coast_s`` the car coasts (0 m/s^2);
3. **brake**: then it brakes at ``fallback_brake_mps2`` until it stands still.

A new command ends the reaction at once. The AV is not affected: the follower drives
behind it and the planner only observes the follower.

A gap at or below zero is a collision (:func:`contact`): the car is put at the AV's rear
bumper and stops there; it never drives through the AV (while the pedal pushes it on, it
stays at the rear bumper, no faster than the AV). A new collision is counted only after the
gap opened to ``COLLISION_CLEAR_M`` again. The AV's rear bumper is known from its odometry,
which is up to a tick old (seconds on a stalled host): :class:`AvTrack` extrapolates it to
now at the AV's speed and its acceleration between its last two messages, so a braking AV is
not placed ahead of where it is (a constant-speed guess was ½·a·age² ahead: 2.5 m for a
second-old message at -5 m/s^2). No rclpy here; times are passed in.
"""

from __future__ import annotations

from dataclasses import dataclass

from trust_av_common.params import check_fields, param

__all__ = ['APPLIED_TOPIC', 'COLLISION_CLEAR_M', 'COMMAND_TOPIC', 'AvTrack', 'FollowerConfig',
           'applied_accel', 'contact']

COMMAND_TOPIC = 'human/accel_cmd'
"""The person's pedal: ``geometry_msgs/msg/AccelStamped``, ``accel.linear.x`` in m/s^2."""
APPLIED_TOPIC = 'human/accel_applied'
"""What the follower plant applied, with the command's header stamp (``AccelStamped``)."""
HOLD, COAST, BRAKE, WAITING = 'hold', 'coast', 'brake', 'waiting'
"""Phases of :func:`applied_accel`: a live command, the two fallback phases, none yet."""


@dataclass(frozen=True)
class FollowerConfig:
    """The participant's car: pedal limits and the reaction to a participant who is gone.

    Attributes:
        accel_max_mps2: full gas, m/s^2 (> 0).
        accel_min_mps2: full brake, m/s^2 (< 0).
        input_timeout_s: commands older than this mean the participant is gone, s.
        coast_s: after the timeout the car coasts this long, s.
        fallback_brake_mps2: then it brakes at this rate to a stop, m/s^2 (< 0).
    """

    accel_max_mps2: float = param('full gas', unit='m/s^2', low=0.0, low_inclusive=False,
                                  default=2.5, high=20.0)
    accel_min_mps2: float = param('full brake', unit='m/s^2', high=0.0,
                                  high_inclusive=False, default=-6.0, low=-20.0)
    input_timeout_s: float = param('no command for this long: the participant is gone',
                                   unit='s', low=0.0, low_inclusive=False, default=0.5, high=60.0)
    coast_s: float = param('after the timeout the car coasts (0 m/s^2) this long', unit='s',
                           low=0.0, default=1.0, high=60.0)
    fallback_brake_mps2: float = param('then it brakes at this rate until it stops',
                                       unit='m/s^2', high=0.0, high_inclusive=False,
                                       default=-2.0, low=-20.0)

    def __post_init__(self) -> None:
        check_fields(self)


def clip_accel(config: FollowerConfig, accel_mps2: float) -> float:
    """The command limited to the pedal's range, m/s^2."""
    return min(config.accel_max_mps2, max(config.accel_min_mps2, accel_mps2))


COLLISION_CLEAR_M = 0.5
"""A contact after the gap opened to this much again is a new collision, m."""


@dataclass(frozen=True)
class AvTrack:
    """The AV as its odometry last showed it, and where its rear bumper is now.

    Attributes:
        position_m: its position in the newest message, m.
        speed_mps: its speed there, m/s.
        accel_mps2: its speed change between its last two messages over their stamps'
            interval, m/s^2 (0 until two have arrived).
        stamp_ns: the newest message's header stamp, ns.
        received_ns: when that message arrived (monotonic), ns.
    """

    position_m: float
    speed_mps: float
    accel_mps2: float
    stamp_ns: int
    received_ns: int

    @classmethod
    def first(cls, position_m: float, speed_mps: float, stamp_ns: int,
              received_ns: int) -> AvTrack:
        """The track from the AV's first message (no acceleration known yet)."""
        return cls(position_m, speed_mps, 0.0, stamp_ns, received_ns)

    def update(self, position_m: float, speed_mps: float, stamp_ns: int,
               received_ns: int) -> AvTrack:
        """The track after the next message; one stamped no later than the newest is not
        newer and changes nothing."""
        interval_s = (stamp_ns - self.stamp_ns) / 1e9
        if interval_s <= 0.0:
            return self
        return AvTrack(position_m, speed_mps, (speed_mps - self.speed_mps) / interval_s,
                       stamp_ns, received_ns)

    def rear_m(self, now_ns: int, length_m: float) -> float:
        """The rear bumper at ``now_ns`` (monotonic): the position advanced over the
        message's age at its speed and acceleration, the AV stopping at 0 m/s (never
        backwards), minus the AV's ``length_m``."""
        age_s = max(0.0, (now_ns - self.received_ns) / 1e9)
        speed, accel = max(0.0, self.speed_mps), self.accel_mps2
        if accel < 0.0:
            age_s = min(age_s, speed / -accel)           # stopped by then
        return self.position_m + speed * age_s + 0.5 * accel * age_s * age_s - length_m


@dataclass(frozen=True)
class Contact:
    """The follower after the collision check: its position and speed, whether it touches
    the AV now and whether that is a new collision."""

    position_m: float
    speed_mps: float
    touching: bool
    new_collision: bool


def contact(position_m: float, speed_mps: float, av_rear_m: float, av_speed_mps: float,
            was_touching: bool) -> Contact:
    """The collision check of the participant's car behind the AV.

    Args:
        position_m: the follower's front bumper, m.
        speed_mps: its speed, m/s.
        av_rear_m: the AV's rear bumper (its position minus the vehicle length), m.
        av_speed_mps: the AV's speed, m/s.
        was_touching: whether the last check found contact (or a gap below
            ``COLLISION_CLEAR_M`` since).

    Returns:
        At a gap <= 0: the car at the rear bumper, stopped on a new collision, else at most as
        fast as the AV; otherwise the car unchanged.
    """
    gap = av_rear_m - position_m
    if gap > 0.0:
        return Contact(position_m, speed_mps, was_touching and gap < COLLISION_CLEAR_M, False)
    new = not was_touching
    speed = 0.0 if new else min(speed_mps, max(0.0, av_speed_mps))
    return Contact(av_rear_m, speed, True, new)


def applied_accel(config: FollowerConfig, command_mps2: float | None,
                  since_command_s: float) -> tuple[float, str]:
    """The acceleration the follower applies now, and the phase it is in.

    Args:
        config: the follower's settings.
        command_mps2: the newest command, m/s^2 (None: none received yet).
        since_command_s: time since that command arrived, s (>= 0).

    Returns:
        (acceleration in m/s^2, phase): :data:`HOLD` (the command, clipped), :data:`COAST`
        (0), :data:`BRAKE` (``fallback_brake_mps2``) or :data:`WAITING` (0: no command yet).
    """
    if command_mps2 is None:
        return 0.0, WAITING
    if since_command_s <= config.input_timeout_s:
        return clip_accel(config, command_mps2), HOLD
    if since_command_s <= config.input_timeout_s + config.coast_s:
        return 0.0, COAST
    return config.fallback_brake_mps2, BRAKE
