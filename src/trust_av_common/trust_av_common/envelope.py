"""The vehicle path's two gates, pure (no rclpy): the values a node takes from a message,
checked against their physical meaning where they are decoded (:class:`InputRanges` and the
``*_problem`` functions), and the command a node sends to an actuator, enforced as its last
step before publishing (:class:`CommandEnvelope`).

Input checks: every field the planner, the trust monitor and the Autoware adapters read is
finite and within :class:`InputRanges` (the ``input_*`` parameters of the ``/**`` section of
``config/trust_av.yaml``); stamps and ``time_from_start`` are valid ``builtin_interfaces``
times (nanoseconds below 1e9, seconds not negative); a trajectory has 1 to
``input_points_max`` points, each with the value the node reads, on strictly increasing
times; frame ids are at most :data:`MAX_FRAME_CHARS` printable characters. A function
returns '' for a usable message, else one line naming the first bad field and its value: the
node drops that message, counts it, names it on ``/diagnostics`` and treats the input as
stale (docs/operations/failures.md). The functions read attribute paths only, so they take
rclpy messages and the light objects of :mod:`trust_av_common.ros.raw_inputs` alike.

Command envelope (after Autoware's ``vehicle_cmd_gate`` filter, ``vehicle_cmd_filter.cpp``:
limit the longitudinal acceleration, then its change per control period by the jerk limit,
and count what was limited): a non-finite command becomes the stale-input deceleration; the
command is clipped to the planner's acceleration bounds and to the jerk limit
``command_jerk_max_mps3`` from the previous command over the control period; every
intervention is counted by reason. A stop command (the hand-over of ``deactivate`` and of an
internal error) is exempt from the jerk limit, as Autoware's emergency stop is, but not from
the bounds. The jerk limit applies in wall mode (the vehicle path); in lock-step (a
simulation, whose commands must stay those of the in-process loop at any ``dt_s``) the
envelope enforces the rest. The defaults leave the shipped runs untouched: the planner's
plans are within its bounds, and at 10 Hz the largest change between two commands within
them, 6 m/s^2 in 0.1 s, is exactly the default jerk limit of 60 m/s^3
(docs/operations/real-vehicle.md, "Command envelope", says how a vehicle sets its own).
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass
from typing import Any

import numpy as np

from trust_av_common.params import check_fields, param, require

__all__ = ['MAX_FRAME_CHARS', 'CommandEnvelope', 'EnvelopeConfig', 'InputRanges',
           'frame_problem', 'odometry_problem', 'stamp_problem', 'trajectory_problem',
           'vector_problem']

MAX_FRAME_CHARS = 256
"""Longest frame id accepted, characters."""
NS_PER_S = 1_000_000_000
RANGES = 'a range of what a message may carry: fixed while the node runs'


@dataclass(frozen=True)
class InputRanges:
    """Physical ranges of the values the vehicle-path nodes take from messages (the
    ``/**`` section: the planner, the trust monitor and the Autoware adapters read the same).

    Attributes:
        input_speed_min_mps: lowest speed accepted (a vehicle rolling back a little), m/s.
        input_speed_max_mps: highest speed accepted, m/s.
        input_position_abs_max_m: largest |position| accepted (positions along the road,
            map coordinates), m.
        input_accel_abs_max_mps2: largest |acceleration| accepted in a plan, m/s^2.
        input_trust_abs_max: largest |value| accepted on the trust topic (E, P, T).
        input_points_max: most points accepted in a trajectory (preview, plans).
    """

    input_speed_min_mps: float = param('lowest speed accepted in an input message (odometry, '
                                       'preview, kinematic state); below it the message is '
                                       'dropped and the input is stale', unit='m/s',
                                       low=-100.0, high=0.0, default=-5.0, reason=RANGES)
    input_speed_max_mps: float = param('highest speed accepted in an input message',
                                       unit='m/s', low=0.0, low_inclusive=False, high=1000.0,
                                       default=100.0, reason=RANGES)
    input_position_abs_max_m: float = param('largest |position| accepted in an input message '
                                            '(along the road, or map x and y)', unit='m',
                                            low=0.0, low_inclusive=False, high=1e12,
                                            default=1e9, reason=RANGES)
    input_accel_abs_max_mps2: float = param('largest |acceleration| accepted in an input '
                                            'plan or command', unit='m/s^2', low=0.0,
                                            low_inclusive=False, high=1000.0, default=100.0,
                                            reason=RANGES)
    input_trust_abs_max: float = param('largest |E|, |P| or |T| accepted on the trust topic',
                                       low=0.0, low_inclusive=False, high=1e12, default=1e6,
                                       reason=RANGES)
    input_points_max: int = param('most points accepted in an input trajectory (preview, '
                                  'plans)', unit='points', low=1, high=1_000_000,
                                  default=10_000, reason=RANGES)

    def __post_init__(self) -> None:
        check_fields(self)
        require(self.input_speed_min_mps < self.input_speed_max_mps,
                'need input_speed_min_mps < input_speed_max_mps, got '
                f'{self.input_speed_min_mps:g}, {self.input_speed_max_mps:g}')


@dataclass(frozen=True)
class EnvelopeConfig:
    """The command envelope's own limit (the acceleration bounds are the planner's)."""

    command_jerk_max_mps3: float = param(
        'largest change of the acceleration command per second between two commands (the '
        "envelope's jerk limit; a stop command is exempt)", unit='m/s^3', low=0.0,
        low_inclusive=False, high=1e6, default=60.0,
        reason='a safety bound: fixed while the vehicle drives')

    def __post_init__(self) -> None:
        check_fields(self)


def _number(name: str, value: Any, low: float, high: float) -> str:
    """'' if ``value`` is a finite number in [low, high], else one line naming it."""
    try:
        number = float(value)
    except (TypeError, ValueError, OverflowError):
        return f'{name} is not a number ({value!r})'
    if not math.isfinite(number):
        return f'{name} is not finite ({number!r})'
    if not low <= number <= high:
        return f'{name} {number!r} outside [{low:g}, {high:g}]'
    return ''


def stamp_problem(name: str, stamp: Any) -> str:
    """'' for a valid ``builtin_interfaces`` Time or Duration (seconds >= 0, nanoseconds
    below 1e9), else one line naming ``name``."""
    sec, nanosec = int(stamp.sec), int(stamp.nanosec)
    if sec < 0 or not 0 <= nanosec < NS_PER_S:
        return f'{name} is not a valid time (sec {sec}, nanosec {nanosec})'
    return ''


def frame_problem(name: str, frame_id: Any) -> str:
    """'' for a frame id of at most :data:`MAX_FRAME_CHARS` printable characters ('' is
    allowed: the node's default), else one line naming ``name``."""
    text = str(frame_id)
    if len(text) > MAX_FRAME_CHARS:
        return f'{name} is {len(text)} characters long (at most {MAX_FRAME_CHARS})'
    if not text.isprintable():
        return f'{name} {text[:40]!r} has non-printable characters'
    return ''


def odometry_problem(msg: Any, ranges: InputRanges) -> str:
    """What the planner reads of a ``nav_msgs/Odometry``: header (stamp, frame_id),
    child_frame_id, ``pose.pose.position.x`` (position along the road) and
    ``twist.twist.linear.x`` (speed). '' if usable."""
    speed_low, speed_high = ranges.input_speed_min_mps, ranges.input_speed_max_mps
    position = ranges.input_position_abs_max_m
    return (stamp_problem('header.stamp', msg.header.stamp)
            or frame_problem('header.frame_id', msg.header.frame_id)
            or frame_problem('child_frame_id', msg.child_frame_id)
            or _number('pose.pose.position.x', msg.pose.pose.position.x, -position, position)
            or _number('twist.twist.linear.x', msg.twist.twist.linear.x, speed_low, speed_high))


def trajectory_problem(msg: Any, field: str, low: float, high: float,
                       points_max: int) -> str:
    """What a node reads of a one-joint ``trajectory_msgs/JointTrajectory``: header, 1 to
    ``points_max`` points, each with at least one value in ``field`` (``velocities`` of a
    preview, ``accelerations`` of a plan; the first is read) within [low, high], on strictly
    increasing ``time_from_start``. '' if usable."""
    problem = (stamp_problem('header.stamp', msg.header.stamp)
               or frame_problem('header.frame_id', msg.header.frame_id))
    if problem:
        return problem
    points = msg.points
    if not 1 <= len(points) <= points_max:
        return f'{len(points)} points (need 1 to {points_max})'
    previous = -1
    for k, point in enumerate(points):
        values = getattr(point, field)
        if len(values) == 0:
            return f'points[{k}] has no {field}'
        problem = (_number(f'points[{k}].{field}[0]', values[0], low, high)
                   or stamp_problem(f'points[{k}].time_from_start', point.time_from_start))
        if problem:
            return problem
        ns = int(point.time_from_start.sec) * NS_PER_S + int(point.time_from_start.nanosec)
        if ns <= previous:
            return f'points[{k}].time_from_start does not increase'
        previous = ns
    return ''


def vector_problem(msg: Any, abs_max: float) -> str:
    """What a node reads of a ``geometry_msgs/Vector3Stamped`` (the trust topic: x = E,
    y = P, z = T): header and the three values within +-``abs_max``. '' if usable."""
    problem = (stamp_problem('header.stamp', msg.header.stamp)
               or frame_problem('header.frame_id', msg.header.frame_id))
    for axis in ('x', 'y', 'z'):
        problem = problem or _number(f'vector.{axis}', getattr(msg.vector, axis), -abs_max,
                                     abs_max)
    return problem


class CommandEnvelope:
    """The last step before an acceleration command is published (see the module
    docstring).

    Args:
        accel_min_mps2, accel_max_mps2: the acceleration bounds, m/s^2.
        jerk_max_mps3: the largest change per second between two commands, m/s^3 (None:
            none; the planner in lock-step, a simulation whose commands must stay those of
            the in-process loop).
        fallback_mps2: what a non-finite command becomes (the stale-input deceleration).

    Attributes:
        counts: commands changed, by reason (``not_finite``, ``accel_bound``,
            ``jerk_bound``).
        commands: commands that passed through.
    """

    REASONS = ('not_finite', 'accel_bound', 'jerk_bound')

    def __init__(self, accel_min_mps2: float, accel_max_mps2: float,
                 jerk_max_mps3: float | None, fallback_mps2: float) -> None:
        if not (math.isfinite(accel_min_mps2) and math.isfinite(accel_max_mps2)
                and accel_min_mps2 < accel_max_mps2):
            raise ValueError(f'need finite accel_min_mps2 < accel_max_mps2, got '
                             f'{accel_min_mps2}, {accel_max_mps2}')
        if jerk_max_mps3 is not None and not (math.isfinite(jerk_max_mps3)
                                              and jerk_max_mps3 > 0.0):
            raise ValueError(f'need a finite jerk limit > 0, got {jerk_max_mps3}')
        if not accel_min_mps2 <= fallback_mps2 <= accel_max_mps2:
            raise ValueError(f'the fallback {fallback_mps2} is outside the bounds')
        self.low, self.high = float(accel_min_mps2), float(accel_max_mps2)
        self.jerk_max_mps3 = jerk_max_mps3
        self.fallback_mps2 = float(fallback_mps2)
        self.previous: float | None = None
        self.counts: Counter[str] = Counter()
        self.commands = 0

    @property
    def clipped(self) -> int:
        """Commands the envelope changed."""
        return sum(self.counts.values())

    def reset(self) -> None:
        """Forget the previous command (``activate``: the jerk limit starts afresh)."""
        self.previous = None

    def command(self, accel_mps2: float, period_s: float, *, stop: bool = False) -> float:
        """The command to publish for ``accel_mps2``, applied for ``period_s`` after the
        previous one; ``stop``: a stop command (not jerk-limited)."""
        self.commands += 1
        value = float(accel_mps2)
        if not math.isfinite(value):
            self.counts['not_finite'] += 1
            value = self.fallback_mps2
        low, high = self.low, self.high
        clipped = min(max(value, low), high)
        if clipped != value:
            self.counts['accel_bound'] += 1
            value = clipped
        if (not stop and self.jerk_max_mps3 is not None and self.previous is not None
                and period_s > 0.0):
            step = self.jerk_max_mps3 * period_s
            limited = min(max(value, self.previous - step), self.previous + step)
            if limited != value:
                self.counts['jerk_bound'] += 1
                value = min(max(limited, low), high)
        self.previous = value
        return value

    def plan(self, plan: np.ndarray, command_mps2: float, tolerance: float) -> np.ndarray:
        """A plan to publish with ``command_mps2`` (what :meth:`command` gave for its first
        value): ``plan`` itself when it is finite, within the bounds to ``tolerance`` and
        starts with the command; else its first value the command and the others finite and
        within the bounds (a non-finite one replaced by the command)."""
        values = np.asarray(plan, dtype=float)
        if (values.size and values[0] == command_mps2 and np.all(np.isfinite(values))
                and float(values.min()) >= self.low - tolerance
                and float(values.max()) <= self.high + tolerance):
            return values
        out = np.where(np.isfinite(values), np.clip(values, self.low, self.high), command_mps2)
        if out.size:
            out[0] = command_mps2
        return out

    def values(self) -> dict[str, str]:
        """For ``/diagnostics``: commands, clipped commands and the count per reason."""
        return {'commands_enveloped': str(self.commands),
                'commands_clipped': str(self.clipped),
                **{f'commands_clipped_{reason}': str(self.counts[reason])
                   for reason in self.REASONS}}

