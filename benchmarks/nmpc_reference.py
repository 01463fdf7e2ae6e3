"""A plain reference NMPC: eq. (12) written out with CasADi ``Opti`` and IPOPT defaults.

Not used in the loop (so not in the packages). It is the baseline ``bench_core.py`` times
our solver against, and an independent statement of the problem that
``tests/core/test_nmpc.py`` compares our plans with: it re-derives the
dynamics, the cost and the Tanimoto distance from the paper instead of calling the
project's helpers. Same inputs as :meth:`trust_av_planner.nmpc.TrustAwareNmpc.step`, with
the trust bound E_max given explicitly.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from preceding_traffic.traces import SpeedTrace
from trust_av.system.config import RunConfig
from trust_av.system.metrics import StepRecord
from trust_av_planner.nmpc import PlannerConfig, TrustAwareNmpc
from trust_monitor.paper_trust import TrustConfig

__all__ = ['ReferenceNmpc', 'compare_on_records']


class ReferenceNmpc:
    """Opti + IPOPT with default options, built once with parameters."""

    def __init__(self, config: PlannerConfig, trust: TrustConfig,
                 ipopt_options: dict[str, Any] | None = None) -> None:
        n, dt = config.horizon_steps, config.dt_s
        opti = ca.Opti()
        u = opti.variable(n)
        self._gap, self._speed = opti.parameter(), opti.parameter()
        self._lead, self._expected = opti.parameter(n), opti.parameter(n)
        self._e_max = opti.parameter()
        d, v = self._gap, self._speed
        tracking: ca.MX = ca.MX(0)
        for k in range(n):
            d = d + (self._lead[k] - v) * dt
            v = v + u[k] * dt
            tracking += (config.standstill_gap_m + config.time_headway_s * v - d) ** 2
            if k > 0:  # d^1 does not depend on the plan
                opti.subject_to(opti.bounded(config.gap_min_m, d, config.gap_max_m))
            opti.subject_to(opti.bounded(config.speed_min_mps, v, config.speed_max_mps))
        a = u + trust.epsilon_mps2
        b = self._expected + trust.epsilon_mps2
        score = 1 - ca.dot(a, b) / ca.sum1(a * a + b * b - a * b)
        opti.subject_to(score <= self._e_max)
        opti.subject_to(opti.bounded(config.accel_min_mps2, u, config.accel_max_mps2))
        opti.minimize(tracking / config.tracking_cost_scale_m2
                      + config.alpha * score / config.explicability_scale)
        options: dict[str, Any] = {'print_level': 0, 'sb': 'yes'}
        options.update(ipopt_options or {})
        opti.solver('ipopt', {'print_time': False}, options)
        self._opti, self._u = opti, u

    def step(self, gap_m: float, speed_mps: float,
              lead_speeds_mps: Sequence[float] | np.ndarray,
              expected_mps2: Sequence[float], explicability_max: float) -> np.ndarray:
        """The reference plan; raises RuntimeError when IPOPT fails."""
        opti = self._opti
        opti.set_value(self._gap, gap_m)
        opti.set_value(self._speed, speed_mps)
        opti.set_value(self._lead, np.asarray(lead_speeds_mps, dtype=float))
        opti.set_value(self._expected, np.asarray(expected_mps2, dtype=float))
        opti.set_value(self._e_max, explicability_max)
        return np.atleast_1d(np.asarray(opti.solve().value(self._u), dtype=float)).ravel()


@dataclass
class Comparison:
    """Our NMPC against the reference on the same inputs (whole-call wall times, s)."""

    ours_s: list[float] = field(default_factory=list)
    reference_s: list[float] = field(default_factory=list)
    plan_differences_mps2: list[float] = field(default_factory=list)
    reference_failures: int = 0

    @property
    def max_plan_difference_mps2(self) -> float:
        """Largest |u_ours - u_reference| over the steps both solved."""
        return max(self.plan_differences_mps2, default=0.0)


def compare_on_records(config: RunConfig, trace: SpeedTrace,
                       records: Sequence[StepRecord]) -> Comparison:
    """Solve every NMPC problem of a closed-loop run again, with ours and with the reference.

    Replays the recorded inputs of each step (gap, speed, preview, expected plan, trust
    before the step) in order, so our solver sees the same warm starts as in the loop; the
    reference gets the trust bound our solver derived. Steps where our solver fell back are
    timed but not compared.
    """
    cfg = config.for_trace(trace)
    ours = TrustAwareNmpc(cfg.planner, cfg.trust)
    reference = ReferenceNmpc(cfg.planner, cfg.trust)
    out = Comparison()
    trust = cfg.trust.trust_initial
    for step, r in enumerate(records):
        preview = trace.preview(step, cfg.planner.horizon_steps)
        start = time.perf_counter()
        plan = ours.step(r.av_gap_m, r.av_speed_mps, preview, np.array(r.expected_plan_mps2),
                          trust)
        out.ours_s.append(time.perf_counter() - start)
        start = time.perf_counter()
        try:
            ref: np.ndarray | None = reference.step(r.av_gap_m, r.av_speed_mps, preview,
                                                     r.expected_plan_mps2,
                                                     plan.explicability_max)
        except RuntimeError:
            ref = None
            out.reference_failures += 1
        out.reference_s.append(time.perf_counter() - start)
        if plan.success and ref is not None:
            out.plan_differences_mps2.append(float(np.max(np.abs(plan.plan_mps2 - ref))))
        trust = r.trust
    return out
