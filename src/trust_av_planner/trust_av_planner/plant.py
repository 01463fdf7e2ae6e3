"""Simulated vehicle plant: integrates odometry (position, speed) from an acceleration.

Kept apart from the planner so that a real vehicle can replace it: the planner only reads
positions and speeds, as a real vehicle's odometry gives them. Explicit Euler with the
same step as the MPC predictions (:mod:`human_driver_sim.longitudinal`), so the gap
``x_lead - x - length`` evolves exactly as ``d += (v_lead - v) dt``.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class VehicleState:
    """Odometry of one vehicle: front-bumper position along the road (m) and speed (m/s)."""

    position_m: float
    speed_mps: float


def integrate(state: VehicleState, accel_mps2: float, dt_s: float) -> VehicleState:
    """One explicit Euler step: x += v dt, v += a dt."""
    return VehicleState(state.position_m + state.speed_mps * dt_s,
                        state.speed_mps + accel_mps2 * dt_s)


def gap_m(lead: VehicleState, follower: VehicleState, vehicle_length_m: float) -> float:
    """Bumper-to-bumper gap from the follower's front to the leader's rear, m."""
    return lead.position_m - follower.position_m - vehicle_length_m
