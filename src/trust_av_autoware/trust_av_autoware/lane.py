"""A lane's centreline as a polyline in a world-fixed frame (``map``), pure (numpy only): the
geometry an adapter from a vehicle stack needs to turn planar poses into the graph's
distances along the road (the planner reads ``pose.position.x`` of its odometry inputs as
that distance).

- :meth:`Centreline.project`: a point's distance along the centreline (arc length from its
  first point, m) and its signed lateral offset (m, left of the direction of travel positive,
  REP-103), from the nearest point of the polyline.
- :meth:`Centreline.along`: a planar velocity's component along the lane there.
- :func:`lead_on_lane`: which of some objects is the lead vehicle: the nearest one ahead of
  the AV whose offset is within half a lane width.

For an Autoware stack (``autoware_planning_msgs``/``nav_msgs/Path`` centreline in ``map``,
``autoware_perception_msgs/PredictedObjects``), see docs/operations/real-vehicle.md.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from trust_av_common.errors import TrustAvError

__all__ = ['Centreline', 'LaneError', 'OnLane', 'lead_on_lane']


class LaneError(TrustAvError):
    """A centreline or a point that cannot be used (one line naming it)."""


@dataclass(frozen=True)
class OnLane:
    """A point's place relative to the centreline.

    Attributes:
        s_m: distance along the centreline from its first point, m (0 before it, the
            length after it: the projection is clamped to the polyline).
        lateral_m: signed distance from the centreline, m (left positive).
        heading_rad: direction of the centreline there, rad (from the frame's x axis).
    """

    s_m: float
    lateral_m: float
    heading_rad: float


class Centreline:
    """A lane's centreline: points ``(x, y)`` in one world-fixed frame, in the direction of
    travel.

    Raises:
        LaneError: fewer than 2 points, a non-finite coordinate, or two consecutive equal
            points (a segment of no direction).
    """

    def __init__(self, points_xy: Sequence[Sequence[float]]) -> None:
        points = np.asarray(points_xy, dtype=float)
        if points.ndim != 2 or points.shape[1] != 2 or len(points) < 2:
            raise LaneError(f'a centreline needs at least 2 points (x, y), got shape '
                            f'{points.shape}')
        if not np.isfinite(points).all():
            raise LaneError('a centreline point is not finite')
        steps = np.diff(points, axis=0)
        lengths = np.hypot(steps[:, 0], steps[:, 1])
        if (lengths <= 0.0).any():
            k = int(np.argmin(lengths))
            raise LaneError(f'centreline points {k} and {k + 1} are equal')
        self.points = points
        self.steps = steps
        self.lengths = lengths
        self.s0 = np.concatenate(([0.0], np.cumsum(lengths)[:-1]))   # s at each segment start
        self.length_m = float(lengths.sum())

    def project(self, x: float, y: float) -> OnLane:
        """``(x, y)``'s distance along and from the centreline (the nearest point of the
        polyline; of equally near ones, the first along it).

        Raises:
            LaneError: a coordinate is not finite.
        """
        if not (np.isfinite(x) and np.isfinite(y)):
            raise LaneError(f'point ({x}, {y}) is not finite')
        rel = np.array([x, y]) - self.points[:-1]
        t = np.clip((rel * self.steps).sum(axis=1) / self.lengths ** 2, 0.0, 1.0)
        nearest = self.points[:-1] + t[:, None] * self.steps
        distance = np.hypot(x - nearest[:, 0], y - nearest[:, 1])
        k = int(np.argmin(distance))
        ux, uy = self.steps[k] / self.lengths[k]
        lateral = ux * (y - nearest[k, 1]) - uy * (x - nearest[k, 0])   # cross: left > 0
        return OnLane(float(self.s0[k] + t[k] * self.lengths[k]), float(lateral),
                      float(np.arctan2(uy, ux)))

    def along(self, place: OnLane, vx: float, vy: float) -> float:
        """The component of the planar velocity ``(vx, vy)`` (in the frame of the points)
        along the lane at ``place``, m/s."""
        return float(vx * np.cos(place.heading_rad) + vy * np.sin(place.heading_rad))


def lead_on_lane(ego_s_m: float, objects: Sequence[OnLane], lane_width_m: float) -> int | None:
    """The index in ``objects`` of the lead vehicle: the one with the smallest distance along
    the lane ahead of ``ego_s_m`` among those within half ``lane_width_m`` of the centreline;
    None if there is none.

    Raises:
        LaneError: ``lane_width_m`` is not positive.
    """
    if not lane_width_m > 0.0:
        raise LaneError(f'lane_width_m must be > 0, got {lane_width_m}')
    ahead = [(o.s_m, k) for k, o in enumerate(objects)
             if o.s_m > ego_s_m and abs(o.lateral_m) <= 0.5 * lane_width_m]
    return min(ahead)[1] if ahead else None
