"""The outcome of one NMPC step (:meth:`trust_av_planner.nmpc.TrustAwareNmpc.step`): the
plan applied, the solver's status and the trust constraint's E_max."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ['PlanResult']


@dataclass(frozen=True)
class PlanResult:
    """Outcome of one NMPC step.

    Attributes:
        plan_mps2: accelerations u_R^0..u_R^{N-1} to apply (solver's or fallback's).
        status: solver return status, or ``fallback: <reason>``.
        success: the solver's plan was used.
        iterations: SQP iterations.
        solve_time_s: wall time of the solver call (instrumentation only).
        explicability_max: E_max of the trust constraint for this step.
        cost: objective value of the returned plan.
        gap_bounds_relaxed: the gap bounds were what the vehicle can reach (status: to what).
    """

    plan_mps2: np.ndarray
    status: str
    success: bool
    iterations: int
    solve_time_s: float
    explicability_max: float
    cost: float = field(default=float('nan'))
    gap_bounds_relaxed: bool = False

    @property
    def fallback(self) -> bool:
        """True when the fallback plan replaced the solver's."""
        return not self.success
