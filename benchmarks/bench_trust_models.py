"""Benchmark of the trust models' NMPC bound: the cost of the numeric derivation.

For every registered trust model, times per call of (a) the numeric bound (bisection on the
model's propagated update, ``model_interface.numeric_bound``) and (b) what the NMPC uses
(the closed form when the model gives one, else the numeric bound), on the 1 Hz grid (3
steps of 1 s) and the 10 Hz grid (30 steps of 0.1 s), from a state just above T_min so
that the bound binds. The bound is computed once per control step, before the solve.

Prints the figures and writes them to benchmarks/results_trust_models.json (or --out).
Not a test: timings are noisy, so nothing here asserts a speed.

    python benchmarks/bench_trust_models.py [--calls 200]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from functools import partial
from pathlib import Path
from typing import Any

from trust_av_common.registry import names
from trust_monitor.model_interface import (
    TRUST_MODELS,
    explicability_bound,
    make_trust_model,
    numeric_bound,
)
from trust_monitor.paper_trust import TrustConfig

GRIDS = {'1 Hz': (3, 1.0), '10 Hz': (30, 0.1)}
BASE = TrustConfig(epsilon_mps2=6.0, trust_growth_rate=0.1, performance_threshold=0.8,
                   trust_initial=0.0)


def per_call_ms(function: Any, calls: int) -> float:
    """Mean wall time of ``function()`` over ``calls`` calls, ms."""
    start = time.perf_counter()
    for _ in range(calls):
        function()
    return 1e3 * (time.perf_counter() - start) / calls


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--calls', type=int, default=200)
    parser.add_argument('--out', type=Path,
                        default=Path(__file__).with_name('results_trust_models.json'))
    args = parser.parse_args()
    results: dict[str, Any] = {'calls': args.calls, 'models': {}}
    for name in names(TRUST_MODELS):
        model = make_trust_model(dataclasses.replace(BASE, trust_model=name))
        state = model.step(model.initial_state(), 0.05, 1.0)
        trust_min = model.trust(state) - 0.01
        row = {}
        for grid, (steps, dt_s) in GRIDS.items():
            bound_args = (model, state, trust_min, steps, dt_s)
            row[grid] = {
                'numeric_ms': per_call_ms(partial(numeric_bound, *bound_args), args.calls),
                'nmpc_ms': per_call_ms(partial(explicability_bound, *bound_args), args.calls),
                'closed_form': model.closed_form_bound is not None}
            print(f'{name:16s} {grid:6s} numeric {row[grid]["numeric_ms"]:7.3f} ms/call, '
                  f'used by the NMPC {row[grid]["nmpc_ms"]:7.3f} ms/call')
        results['models'][name] = row
    args.out.write_text(json.dumps(results, indent=2) + '\n')
    print(f'wrote {args.out}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
