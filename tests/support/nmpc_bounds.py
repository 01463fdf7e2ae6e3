"""The tests' oracle of the NMPC's constraints: how far a plan breaks the bounds of eq. (12)."""

from __future__ import annotations

import numpy as np

from trust_av_planner.nmpc import TrustAwareNmpc


def bound_violation(nmpc: TrustAwareNmpc, plan: np.ndarray, gap_m: float, speed_mps: float,
                    lead_speeds_mps: np.ndarray, expected_mps2: np.ndarray,
                    explicability_max: float, reachable: bool = False) -> float:
    """Largest violation of any bound of eq. (12) by ``plan`` (0 when all hold); with
    ``reachable``, of the gap bounds the vehicle can reach instead of d_min and d_max (the
    NMPC's own checks, :meth:`TrustAwareNmpc._violation`)."""
    lower, upper = nmpc.bounds(explicability_max)
    if reachable:
        lower, upper, _ = nmpc._reachable_gap_bounds(lower, upper, gap_m, speed_mps,
                                                     lead_speeds_mps)
    return nmpc._violation(plan, gap_m, speed_mps, lead_speeds_mps, expected_mps2, lower,
                           upper)
