"""From an Autoware stack's planar world to the planner's longitudinal inputs, pure (no rclpy):
the AV's pose and the perceived objects in ``map`` become distances along a lane's centreline
(:class:`~trust_av_autoware.lane.Centreline`) and speeds along it, as the planner reads its
odometry inputs (``pose.position.x`` = the front bumper's distance along the road,
``twist.twist.linear.x`` = speed, the gap = lead x − AV x − ``vehicle_length_m``).

- :func:`ego_on_lane`: the AV from its kinematic state (base_link pose in ``map``, body-frame
  twist) -> its front bumper's distance along the lane and its speed along it.
- :func:`lead_from_objects`: the lead vehicle among the perceived objects (the nearest one
  ahead within half a lane width, :func:`~trust_av_autoware.lane.lead_on_lane`) -> the
  position to publish, chosen so that the planner's gap is the real one: from the AV's front
  bumper to the lead's rear.

Every value is checked here, where it enters: a message field that is not finite, a zero
quaternion, an AV off its lane raise :class:`InputError` with one line naming it; the node
drops that message and counts it under :attr:`InputError.kind`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from trust_av_autoware.lane import Centreline, LaneError, OnLane, lead_on_lane
from trust_av_common.errors import TrustAvError
from trust_av_common.params import MAX_VEHICLE_LENGTH_M, check_fields, param

__all__ = ['BOUNDING_BOX', 'CYLINDER', 'POLYGON', 'InputError', 'LaneAdapterConfig', 'LaneState',
           'Lead', 'Planar', 'Seen', 'centreline_from_points', 'check_frame', 'ego_on_lane',
           'finite', 'half_length_m', 'lead_from_objects', 'seen', 'yaw']

BOUNDING_BOX, CYLINDER, POLYGON = 0, 1, 2
"""``autoware_perception_msgs/msg/Shape`` types (its constants)."""


class InputError(TrustAvError):
    """A message that cannot be used: one line naming the bad thing; ``kind`` is the counter
    it is dropped under (``frame``, ``not_finite``, ``off_lane``, ...)."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


@dataclass(frozen=True)
class LaneAdapterConfig:
    """The ``autoware_lane`` adapter node (docs/operations/real-vehicle.md)."""

    vehicle_length_m: float = param('vehicle length the planner subtracts from the positions '
                                    '(the shared /** value of the params file)', unit='m',
                                    low=0.0, high=MAX_VEHICLE_LENGTH_M)
    frame_id: str = param('world-fixed frame of the centreline, the kinematic state and the '
                          'objects (Autoware: map); also the frame_id of the outputs',
                          default='map')
    lane_width_m: float = param('lane width: an object whose centre is within half of it of '
                                'the centreline is on the lane; the AV must be too', unit='m',
                                low=0.0, low_inclusive=False, high=50.0, default=3.5)
    base_link_to_front_m: float = param(
        "from the AV's base_link (Autoware: rear axle centre) to its front bumper along x "
        '(Autoware vehicle_info: wheel_base + front_overhang)', unit='m', low=0.0,
        high=MAX_VEHICLE_LENGTH_M, default=3.79)
    ego_timeout_s: float = param('objects are used only while the newest kinematic state is '
                                 'at most this old', unit='s', low=0.0, low_inclusive=False,
                                 high=3600.0, default=0.5)

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class Planar:
    """A pose and a body-frame velocity in the lane's frame.

    Attributes:
        x_m, y_m: position, m.
        yaw_rad: heading of the body's x axis, rad.
        vx_mps, vy_mps: velocity in the body frame (Autoware's twists), m/s.
    """

    x_m: float
    y_m: float
    yaw_rad: float
    vx_mps: float
    vy_mps: float

    def velocity_in_frame(self) -> tuple[float, float]:
        """The velocity rotated into the lane's frame, m/s."""
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        return c * self.vx_mps - s * self.vy_mps, s * self.vx_mps + c * self.vy_mps


@dataclass(frozen=True)
class LaneState:
    """What the planner gets for one vehicle.

    Attributes:
        position_m: the distance along the lane it is published at, m.
        speed_mps: its speed along the lane, m/s.
        lateral_m: its centre's offset from the centreline, m (left positive).
    """

    position_m: float
    speed_mps: float
    lateral_m: float


def finite(kind: str, **values: float) -> None:
    """Raise :class:`InputError` ``not_finite`` naming the first value that is not finite."""
    for name, value in values.items():
        if not math.isfinite(value):
            raise InputError(kind, f'{name} is not finite ({value!r})')


def in_range(name: str, value: float, low: float, high: float) -> None:
    """Raise :class:`InputError` ``out_of_range`` unless ``value`` is within [low, high]
    (the ``input_*`` ranges, :class:`trust_av_common.envelope.InputRanges`)."""
    if not low <= value <= high:
        raise InputError('out_of_range', f'{name} {value!r} outside [{low:g}, {high:g}]')


def yaw(qx: float, qy: float, qz: float, qw: float, what: str) -> float:
    """The heading (rotation about z) of a quaternion, rad.

    Raises:
        InputError: ``not_finite``: a component is not finite; ``bad_orientation``: a zero
            quaternion.
    """
    finite('not_finite', **{f'{what} orientation.{k}': v
                            for k, v in (('x', qx), ('y', qy), ('z', qz), ('w', qw))})
    if qx * qx + qy * qy + qz * qz + qw * qw < 1e-12:
        raise InputError('bad_orientation', f'{what} orientation is the zero quaternion')
    return math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))


def check_frame(frame_id: str, expected: str, what: str) -> None:
    """Raise :class:`InputError` ``frame`` unless ``frame_id`` is ``expected``."""
    if frame_id != expected:
        raise InputError('frame', f"{what} in frame '{frame_id}', expected '{expected}'")


def centreline_from_points(points: Sequence[tuple[float, float]]) -> Centreline:
    """The centreline of a path's points; consecutive duplicates (a path with a repeated
    pose) are dropped first.

    Raises:
        InputError: ``bad_centreline``: fewer than 2 distinct points or a non-finite one.
    """
    kept: list[tuple[float, float]] = []
    for point in points:
        if not kept or point != kept[-1]:
            kept.append(point)
    try:
        return Centreline(kept)
    except LaneError as error:
        raise InputError('bad_centreline', f'centreline: {error}') from error


def ego_on_lane(lane: Centreline, ego: Planar, config: LaneAdapterConfig) -> LaneState:
    """The AV (its base_link) on the lane: its front bumper's distance along the lane (base_link
    + ``base_link_to_front_m``) and its speed along the lane.

    Raises:
        InputError: ``not_finite`` (a value), ``off_lane``: farther than half
            ``lane_width_m`` from the centreline (also beyond either end of it).
    """
    finite('not_finite', x=ego.x_m, y=ego.y_m, vx=ego.vx_mps, vy=ego.vy_mps)
    place = lane.project(ego.x_m, ego.y_m)
    end_gap = _beyond_end(lane, place, ego.x_m, ego.y_m)
    if abs(place.lateral_m) > 0.5 * config.lane_width_m or end_gap > 0.5 * config.lane_width_m:
        raise InputError('off_lane', f'AV {max(abs(place.lateral_m), end_gap):.2f} m off the '
                         f'lane (half width {0.5 * config.lane_width_m:g} m)')
    vx, vy = ego.velocity_in_frame()
    return LaneState(place.s_m + config.base_link_to_front_m, lane.along(place, vx, vy),
                     place.lateral_m)


def _beyond_end(lane: Centreline, place: OnLane, x: float, y: float) -> float:
    """How far a point clamped to an end of the centreline lies beyond it, m (0 inside)."""
    if 0.0 < place.s_m < lane.length_m:
        return 0.0
    end = lane.points[0] if place.s_m <= 0.0 else lane.points[-1]
    return float(math.hypot(x - end[0], y - end[1]))


def half_length_m(shape_type: int, dimensions_x_m: float, footprint_x_m: Sequence[float]) -> float:
    """From an object's centre to its rear along its x axis, m: half ``dimensions.x`` of a
    bounding box or a cylinder (its diameter), the rearmost footprint point of a polygon.

    Raises:
        InputError: ``not_finite``, ``bad_shape`` (an unknown type, a negative size, a
            polygon without points).
    """
    finite('not_finite', **{'shape.dimensions.x': dimensions_x_m},
           **{f'shape.footprint[{k}].x': x for k, x in enumerate(footprint_x_m)})
    if shape_type in (BOUNDING_BOX, CYLINDER):
        if dimensions_x_m < 0.0:
            raise InputError('bad_shape', f'shape.dimensions.x is negative ({dimensions_x_m})')
        return 0.5 * dimensions_x_m
    if shape_type == POLYGON:
        if not footprint_x_m:
            raise InputError('bad_shape', 'a POLYGON shape without footprint points')
        return max(0.0, -min(footprint_x_m))
    raise InputError('bad_shape', f'unknown shape type {shape_type}')


@dataclass(frozen=True)
class Seen:
    """One perceived object: its centre's pose and body-frame twist, and its rear."""

    pose: Planar
    half_length_m: float


@dataclass(frozen=True)
class Lead:
    """The chosen lead vehicle.

    Attributes:
        index: its index among the objects of the message.
        state: what the planner gets (``position_m`` = the lead's rear + ``vehicle_length_m``,
            so the planner's gap = the lead's rear − the AV's front bumper).
        gap_m: that gap, m.
    """

    index: int
    state: LaneState
    gap_m: float


def lead_from_objects(lane: Centreline, ego: LaneState, ego_base_s_m: float,
                      objects: Sequence[Seen], config: LaneAdapterConfig) -> Lead | None:
    """The lead vehicle: of ``objects``, the one whose centre is nearest ahead of the AV's
    base_link (``ego_base_s_m``) along the lane within half ``lane_width_m`` of the
    centreline; None if none is.

    Args:
        lane: the centreline.
        ego: the AV as :func:`ego_on_lane` gave it.
        ego_base_s_m: the AV's base_link distance along the lane, m.
        objects: the objects (checked finite by the caller: :func:`seen`).
        config: the adapter's settings.
    """
    places = [lane.project(o.pose.x_m, o.pose.y_m) for o in objects]
    index = lead_on_lane(ego_base_s_m, places, config.lane_width_m)
    if index is None:
        return None
    place, lead = places[index], objects[index]
    vx, vy = lead.pose.velocity_in_frame()
    rear_m = place.s_m - lead.half_length_m
    return Lead(index, LaneState(rear_m + config.vehicle_length_m, lane.along(place, vx, vy),
                                 place.lateral_m), rear_m - ego.position_m)


def seen(pose: Planar, half_length: float) -> Seen:
    """An object, its values checked.

    Raises:
        InputError: ``not_finite``.
    """
    finite('not_finite', x=pose.x_m, y=pose.y_m, vx=pose.vx_mps, vy=pose.vy_mps)
    return Seen(pose, half_length)
