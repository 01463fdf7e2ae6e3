"""Longitudinal point-mass dynamics shared by every vehicle model (explicit time step).

Paper eq. (5) written with an explicit step (docs/concepts/reading-the-paper.md, "Time step
and horizon")::

    d[k+1] = d[k] + (v_lead[k] - v[k]) * dt
    v[k+1] = v[k] + u[k] * dt

The functions use plain arithmetic, so they accept floats or CasADi symbols: the NMPCs (the
AV's and the human's) build their predictions and the simulator integrates the plants with
the same lines. A vehicle's odometry is :class:`VehicleState` (what a real vehicle
publishes: position along the road and speed); :func:`integrate` advances it with the same
explicit Euler step, so the gap ``x_lead - x - length`` evolves exactly as
``d += (v_lead - v) dt``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

__all__ = ['Collision', 'VehicleState', 'advance', 'collision', 'gap_m', 'hardest_plan',
           'hold_gap_plan', 'integrate', 'lead_speeds', 'reachable_gap_bounds', 'rollout', 'step']


@dataclass(frozen=True)
class VehicleState:
    """Odometry of one vehicle: front-bumper position along the road (m) and speed (m/s)."""

    position_m: float
    speed_mps: float


def integrate(state: VehicleState, accel_mps2: float, dt_s: float) -> VehicleState:
    """One explicit Euler step: x += v dt, v += a dt, the speed never below 0 (no
    reversing; a command that brakes exactly to a stop, a = -v / dt, leaves rounding such as
    -2e-18 m/s or -0.0, which is reported as 0.0)."""
    speed = state.speed_mps + accel_mps2 * dt_s
    return VehicleState(state.position_m + state.speed_mps * dt_s,
                        0.0 if speed <= 0.0 else speed)   # NaN stays NaN


def gap_m(lead: VehicleState, follower: VehicleState, vehicle_length_m: float) -> float:
    """Bumper-to-bumper gap from the follower's front to the leader's rear, m."""
    return lead.position_m - follower.position_m - vehicle_length_m


@dataclass(frozen=True)
class Collision:
    """Two vehicles touched: a bumper-to-bumper gap at or below zero.

    Attributes:
        step: the control step whose start state holds the gap (0-based).
        t_s: its time, s.
        front: the vehicle ahead (``preceding traffic`` or ``AV``).
        rear: the vehicle that reached it (``AV`` or ``human``).
        gap_m: the gap, m (<= 0).
    """

    step: int
    t_s: float
    front: str
    rear: str
    gap_m: float

    def line(self) -> str:
        """One line naming the step and the vehicles, e.g. ``collision at step 41 (t = 41.0
        s): the AV reached the preceding traffic (gap -0.73 m)``."""
        return (f'collision at step {self.step} (t = {self.t_s:g} s): the {self.rear} reached '
                f'the {self.front} (gap {self.gap_m:.2f} m)')

    def short(self) -> str:
        """For a summary table: ``step 41, AV into preceding traffic``."""
        return f'step {self.step}, {self.rear} into {self.front}'


def collision(step: int, t_s: float, av_gap_m: float,
              human_gap_m: float | None = None) -> Collision | None:
    """The collision a step's gaps show, or None: the AV's gap to the preceding traffic at
    or below 0 m (named first when both are), else the human's gap to the AV at or below
    0 m. A NaN gap is not a collision (the loop's output checks refuse it).

    Args:
        step: the control step (0-based).
        t_s: its time, s.
        av_gap_m: the AV's gap to the preceding traffic, m.
        human_gap_m: the human's gap to the AV, m (None: no follower, e.g. a drive whose
            follower state is not known).
    """
    if av_gap_m <= 0.0:
        return Collision(step, t_s, 'preceding traffic', 'AV', float(av_gap_m))
    if human_gap_m is not None and human_gap_m <= 0.0:
        return Collision(step, t_s, 'AV', 'human', float(human_gap_m))
    return None


def advance(position_m: float, speed_mps: float, accel_mps2: float,
            dt_s: float) -> tuple[float, float]:
    """A simulated vehicle over ``dt_s`` of wall time (wall mode of ``ego_plant`` and
    ``human_driver``): explicit Euler like :func:`integrate`, x += v dt, v += a dt, the
    speed stopping at 0 (a vehicle braking to a stop does not reverse within a long tick).
    Returns (position_m, speed_mps).

    Raises:
        ValueError: ``dt_s`` is negative.
    """
    if dt_s < 0.0:
        raise ValueError(f'dt_s must be >= 0, got {dt_s}')
    speed = speed_mps + accel_mps2 * dt_s
    return position_m + speed_mps * dt_s, 0.0 if speed <= 0.0 else speed   # -0.0 too


def step(gap_m: Any, speed_mps: Any, lead_speed_mps: Any, accel_mps2: Any,
         dt_s: float) -> tuple[Any, Any]:
    """Advance (gap, speed) by one step; the gap is bumper to bumper to the leader."""
    return gap_m + (lead_speed_mps - speed_mps) * dt_s, speed_mps + accel_mps2 * dt_s


def rollout(gap_m: Any, speed_mps: Any, lead_speeds_mps: Sequence[Any],
            accels_mps2: Sequence[Any], dt_s: float) -> tuple[list[Any], list[Any]]:
    """Predicted gaps and speeds at steps 1..N for a plan of N accelerations.

    Returns:
        (gaps, speeds), each of length N: the states the plan leads to.
    """
    gaps: list[Any] = []
    speeds: list[Any] = []
    for lead, accel in zip(lead_speeds_mps, accels_mps2, strict=True):
        gap_m, speed_mps = step(gap_m, speed_mps, lead, accel, dt_s)
        gaps.append(gap_m)
        speeds.append(speed_mps)
    return gaps, speeds


def lead_speeds(speed_mps: Any, accels_mps2: Sequence[Any], dt_s: float) -> list[Any]:
    """Speeds of a vehicle at steps 0..N-1 when it applies ``accels_mps2`` from ``speed_mps``."""
    out = [speed_mps]
    for accel in accels_mps2[:-1]:
        out.append(out[-1] + accel * dt_s)
    return out


def hardest_plan(speed_mps: float, steps: int, dt_s: float, accel_min_mps2: float,
                 accel_max_mps2: float, speed_limit_mps: float, *, braking: bool) -> list[float]:
    """The hardest braking plan (``accel_min_mps2`` at every step, never below
    ``speed_limit_mps``: it never reverses) or the hardest accelerating one (``accel_max_mps2``,
    never above it). They give the largest and the smallest gap at every step against any
    plan within the bounds, so a lower (upper) gap bound is feasible exactly when the braking
    (accelerating) plan meets it."""
    plan = []
    for _ in range(steps):
        to_limit = (speed_limit_mps - speed_mps) / dt_s
        accel = max(accel_min_mps2, to_limit) if braking else min(accel_max_mps2, to_limit)
        accel = min(max(accel, accel_min_mps2), accel_max_mps2)
        plan.append(accel)
        speed_mps += accel * dt_s
    return plan


def reachable_gap_bounds(gap_min_m: float, gap_max_m: float, gap_m: float, speed_mps: float,
                         lead_speeds_mps: Sequence[float], dt_s: float, accel_min_mps2: float,
                         accel_max_mps2: float, speed_min_mps: float,
                         speed_max_mps: float) -> tuple[list[float], list[float]]:
    """Gap bounds at steps 1..N that some plan within the acceleration and speed bounds
    meets: ``gap_min_m``, or where even the hardest braking (:func:`hardest_plan`) ends
    closer, what it reaches; ``gap_max_m``, or where even the hardest acceleration ends
    further, what it reaches (d^1 does not depend on the plan, and every later gap falls as
    the plan rises)."""
    steps, lead = len(lead_speeds_mps), list(lead_speeds_mps)
    low = rollout(gap_m, speed_mps, lead, hardest_plan(
        speed_mps, steps, dt_s, accel_min_mps2, accel_max_mps2, speed_min_mps, braking=True),
        dt_s)[0]
    high = rollout(gap_m, speed_mps, lead, hardest_plan(
        speed_mps, steps, dt_s, accel_min_mps2, accel_max_mps2, speed_max_mps, braking=False),
        dt_s)[0]
    return [min(gap_min_m, g) for g in low], [max(gap_max_m, g) for g in high]


def hold_gap_plan(gap_m: float, speed_mps: float, lead_speeds_mps: Sequence[float], *,
                  dt_s: float, standstill_gap_m: float, time_headway_s: float,
                  gap_gain_per_s2: float, speed_gain_per_s: float, accel_min_mps2: float,
                  accel_max_mps2: float, speed_min_mps: float,
                  speed_max_mps: float) -> list[float]:
    """Safe fallback plan: a saturated constant-time-headway controller, rolled out.

    ``u = k_d (d - d_s - tau v) + k_v (v_lead - v)``, then limited so that the gap two steps
    ahead (the first one an acceleration can change) stays >= d_s if the leader keeps its
    previewed speed, then clipped to what keeps the next speed within [speed_min, speed_max]
    (never reversing) and last to the acceleration bounds, which always hold: from a speed
    outside the speed bounds the plan returns towards them at the bounded acceleration (an
    ego speed of 500 m/s against a 36 m/s bound gives ``accel_min_mps2``, not
    (36 - 500) / dt). A speed or gap that is not finite gives a plan that is not finite (the
    caller's envelope replaces it). Used when an MPC has no solution.
    """
    plan: list[float] = []
    leads = list(lead_speeds_mps)
    for k, lead in enumerate(leads):
        next_lead = leads[min(k + 1, len(leads) - 1)]
        next_gap = gap_m + (lead - speed_mps) * dt_s
        accel = (gap_gain_per_s2 * (gap_m - standstill_gap_m - time_headway_s * speed_mps)
                 + speed_gain_per_s * (lead - speed_mps))
        # d[k+2] = d[k+1] + (v_lead[k+1] - v[k] - u dt) dt >= d_s
        accel = min(accel, ((next_gap - standstill_gap_m) / dt_s + next_lead - speed_mps) / dt_s)
        accel = min(max(accel, (speed_min_mps - speed_mps) / dt_s),
                    (speed_max_mps - speed_mps) / dt_s)
        accel = min(max(accel, accel_min_mps2), accel_max_mps2)
        plan.append(accel)
        gap_m, speed_mps = step(gap_m, speed_mps, lead, accel, dt_s)
    return plan
