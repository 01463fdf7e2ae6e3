"""Coordinate frame ids (REP-105) as parameters, and the planner's check of its inputs' frames.

REP-105 (https://www.ros.org/reps/rep-0105.html) names a vehicle's frames ``map`` and
``odom`` (world-fixed) and ``base_link`` (the body). The graph publishes odometry in ``odom``
with each vehicle's body frame as child (:mod:`trust_av_common.topics`). The planner
reads ``pose.position.x`` of the lead's and the AV's odometry as distances along the road:
that holds only when both are in the same world-fixed frame, which it checks
(:func:`position_frame_problem`) instead of assuming. Its plans and commands are in the AV's
body frame: the ``child_frame_id`` of the AV's odometry as the vehicle stack names it, or
``base_frame_id`` before the first odometry arrives (:func:`body_frame`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from trust_av_common.params import check_fields, param, require

__all__ = ['FrameConfig', 'body_frame', 'position_frame_problem']

STARTUP = 'the frames of the outputs are fixed at start-up'


@dataclass(frozen=True)
class FrameConfig:
    """Frame ids of the planner's inputs and outputs (REP-105 defaults).

    Attributes:
        map_frame_id: a world-fixed frame (REP-105 ``map``) in which input positions are
            accepted.
        odom_frame_id: the world-fixed frame (REP-105 ``odom``) in which input positions
            are accepted; the graph's own odometry is in it.
        base_frame_id: the AV's body frame (REP-105 ``base_link``): the ``frame_id`` of
            the plans and the acceleration command until the AV's odometry names its
            ``child_frame_id``.
    """

    map_frame_id: str = param('REP-105 map: a world-fixed frame input positions may be in',
                              default='map', reason=STARTUP)
    odom_frame_id: str = param('REP-105 odom: a world-fixed frame input positions may be in',
                               default='odom', reason=STARTUP)
    base_frame_id: str = param("REP-105 base_link: the AV's body frame, frame_id of plans and "
                               "commands until the AV's odometry names its child_frame_id",
                               default='base_link', reason=STARTUP)

    def __post_init__(self) -> None:
        check_fields(self)
        for name in ('map_frame_id', 'odom_frame_id', 'base_frame_id'):
            value = getattr(self, name)
            require(bool(value) and not value.startswith('/') and value.strip() == value,
                    f'{name} must be a tf2 frame id (not empty, no leading /, no spaces '
                    f'around it), got {value!r}')

    @property
    def world_frames(self) -> tuple[str, str]:
        """The frames input positions may be in."""
        return self.odom_frame_id, self.map_frame_id


def position_frame_problem(frames: Mapping[str, str], config: FrameConfig) -> str:
    """Why the positions of these inputs cannot be compared ('' if they can).

    Args:
        frames: input name -> the ``header.frame_id`` of its latest odometry.
        config: the accepted world-fixed frames.

    Returns:
        '' when every input is in the same one of ``config.world_frames``; else one line
        naming the inputs and their frames.
    """
    outside = [f'{name} in {frame!r}' for name, frame in frames.items()
               if frame not in config.world_frames]
    if outside:
        return (f'frame_id not {config.odom_frame_id!r} or {config.map_frame_id!r}: '
                f'{", ".join(outside)}')
    if len(set(frames.values())) > 1:
        return 'positions in different frames: ' + ', '.join(
            f'{name} in {frame!r}' for name, frame in frames.items())
    return ''


def body_frame(child_frame_id: str, config: FrameConfig) -> str:
    """The AV's body frame: its odometry's ``child_frame_id``, else ``base_frame_id``."""
    return child_frame_id or config.base_frame_id
