"""Names for the values that travel in repurposed message types, pure (no rclpy), so that
plotting tools label them: trust travels as ``geometry_msgs/Vector3Stamped`` (x = E, y = P,
z = trust) and plans as a one-joint ``trajectory_msgs/JointTrajectory`` (the acceleration of
the joint ``longitudinal`` at each point's ``time_from_start``). The ``field_labels`` node
republishes both as ``sensor_msgs/JointState`` with these names in ``name`` and the values in
``position``: PlotJuggler shows each as ``<topic>/<name>/position``, Foxglove's message path
``<topic>.position[<index>]`` with the name beside it in ``name``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

__all__ = ['TRUST_NAMES', 'finite_values', 'plan_names']

TRUST_NAMES = ('explicability', 'performance', 'trust')
"""``vector.x``, ``vector.y``, ``vector.z`` of ``trust_monitor/trust`` (dimensionless)."""


def plan_names(times_s: Sequence[float]) -> list[str]:
    """One name per plan point: ``accel_mps2_at_<t>s`` (``time_from_start`` t, s)."""
    return [f'accel_mps2_at_{t:g}s' for t in times_s]


def finite_values(values: Sequence[float]) -> bool:
    """Whether every value may be republished (a non-finite one is dropped and counted)."""
    return all(math.isfinite(v) for v in values)
