"""In-process runs with the shipped configuration, cached per test process."""

from __future__ import annotations

import dataclasses
import functools

from preceding_traffic.sources import load_trace
from preceding_traffic.traces import SpeedTrace
from trust_av.system.closed_loop import SimResult, simulate
from trust_av.system.config import RunConfig, load_run_config

ALPHAS = (0.0, 0.25, 0.5, 0.75, 1.0)


def with_alpha(config: RunConfig, alpha: float, predictor: str = 'ca') -> RunConfig:
    """``config`` with another alpha and predictor."""
    return dataclasses.replace(
        config, planner=dataclasses.replace(config.planner, alpha=alpha, predictor=predictor))


@functools.cache
def shipped_trace(name: str) -> SpeedTrace:
    """A shipped trace on the default grid."""
    config = load_run_config()
    return load_trace(name, config.planner.dt_s, config.trace)


@functools.cache
def closed_loop(trace: str, alpha: float, predictor: str = 'ca') -> SimResult:
    """One whole-trace in-process run with the shipped configuration (cached)."""
    return simulate(with_alpha(load_run_config(), alpha, predictor), shipped_trace(trace))
