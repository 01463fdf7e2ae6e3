"""Example trust model of a plug-in package: the paper's update with forgetting.

Trust relaxes towards a baseline with time constant ``leaky_time_constant_s`` while the
paper's input u_T (eq. 11) drives it: ``dT/dt = delta u_T - (T - T_base) / tau``. The
update over ``dt`` is the ODE's exact solution for a constant plan, so ten 0.1 s steps equal
one 1 s step to rounding (the contract of ``trust_monitor.model_interface``), and the
model's own discrete equation is that 1 s step. No closed form for the NMPC bound is given:
the planner bisects on :meth:`LeakyTrustModel.step`.

Registered by the package's ``pyproject.toml``::

    [project.entry-points."trust_av.trust_models"]
    leaky = "trust_av_example_plugin.leaky_trust:COMPONENT"

then ``trust_model: leaky`` in a params file (and ``leaky_time_constant_s`` beside it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from trust_av_common.params import check_fields, param
from trust_av_common.registry import Component
from trust_monitor.paper_trust import SAME_MODEL, TrustConfig, performance, trust_input


@dataclass(frozen=True)
class LeakyConfig:
    """Parameters of ``leaky`` (named after the model: one flat ROS namespace).

    Attributes:
        leaky_time_constant_s: tau, how long trust takes to forget (1/e), s.
        leaky_baseline: T_base, the trust it forgets towards, trust units.
    """

    leaky_time_constant_s: float = param('time constant of forgetting', unit='s', low=0.0,
                                         low_inclusive=False, reason=SAME_MODEL,
                                         default=300.0)
    leaky_baseline: float = param('trust it relaxes towards', reason=SAME_MODEL,
                                  default=0.0)

    def __post_init__(self) -> None:
        check_fields(self)


class LeakyTrustModel:
    """``T(t + dt) = T_inf + (T - T_inf) exp(-dt / tau)``, ``T_inf = T_base + tau delta u_T``;
    the state is T."""

    name = 'leaky'
    closed_form_bound = None

    def __init__(self, config: TrustConfig, params: LeakyConfig) -> None:
        self.config = config
        self.params = params

    def initial_state(self) -> float:
        """T(0) = ``trust_initial``."""
        return self.config.trust_initial

    def step(self, state: float, score: float, dt_s: float) -> float:
        """Exact update over ``dt_s`` s with E = ``score`` held.

        Raises:
            ValueError: ``dt_s`` negative or not finite.
        """
        if not (math.isfinite(dt_s) and dt_s >= 0.0):
            raise ValueError(f'dt_s must be finite and >= 0, got {dt_s}')
        tau = self.params.leaky_time_constant_s
        u = trust_input(performance(score), self.config.performance_threshold)
        target = self.params.leaky_baseline + tau * self.config.trust_growth_rate * u
        return target + (state - target) * math.exp(-dt_s / tau)

    def trust(self, state: float) -> float:
        """T itself."""
        return state

    def variance(self, state: float) -> float | None:
        """None: deterministic."""
        return None


COMPONENT = Component('leaky', LeakyTrustModel, LeakyConfig,
                      description='example plug-in: eqs. (9)-(11) with forgetting')
