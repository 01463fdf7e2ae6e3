"""The 1 Hz vs 10 Hz table of docs/RESULTS.md ("Control rate"): the in-process closed loop on
US06 and commute_am, TAC-CA and TAC-GRU, alpha 0 and 1, at the paper's 1 Hz and at 10 Hz
(``trust-av simulate --control-rate-hz``). Prints one Markdown row per case, with two
measured causes of the differences in mean E: the RMS change of the AV's acceleration from one
1 s step to the next (1 s means at the faster rate), and the faster loop's mean E just after
the 1 s expectation is refreshed and just before the next refresh (docs/MODEL.md, "Time
consistency").

Usage: python scripts/rate_table.py [--max-steps-s S] [--traces us06,commute_am] [--rate-hz 10]
"""

from __future__ import annotations

import argparse
import time

from preceding_traffic.traces import truncate
from trust_av.system.closed_loop import control_trace, simulate
from trust_av.system.config import load_run_config
from trust_av.system.metrics import (
    explicability_by_age,
    step_change_rms_mps2,
    ticks_per_model_step,
)


def rel(a: float, b: float) -> str:
    """(b - a) / a in percent."""
    return f'{100.0 * (b - a) / a:+.1f} %'


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--traces', default='us06,commute_am')
    parser.add_argument('--predictors', default='ca,gru')
    parser.add_argument('--alphas', default='0,1')
    parser.add_argument('--max-steps-s', type=float, default=0.0,
                        help='only the first S seconds of each trace (0: all)')
    parser.add_argument('--rate-hz', type=float, default=10.0,
                        help='the control rate compared with 1 Hz (default 10)')
    args = parser.parse_args()
    if not args.rate_hz > 0.0:
        parser.error(f'--rate-hz must be > 0, got {args.rate_hz}')
    hz = f'{args.rate_hz:g} Hz'
    print(f'| trace | predictor | alpha | final trust 1 / {hz} | mean E 1 / {hz} | '
          f'RMSE 1 / {hz} (m/s^2) | min AV gap {hz} (m) | unsafe / fallback / standstill '
          f'fallback {hz} | 1 s accel change RMS 1 / {hz} (m/s^2) | mean E {hz}: '
          f'expectation just refreshed / a period before the next | wall {hz} (s) |')
    print('|---|---|---|---|---|---|---|---|---|---|---|')
    for trace in args.traces.split(','):
        for predictor in args.predictors.split(','):
            for alpha in (float(a) for a in args.alphas.split(',')):
                config = load_run_config(overrides={
                    'planner': {'alpha': alpha, 'predictor': predictor},
                    'preceding_traffic': {'trace': trace}})
                metrics, records = {}, {}
                for rate in (1.0, args.rate_hz):
                    loop_trace = control_trace(config, rate)
                    if args.max_steps_s:
                        loop_trace = truncate(loop_trace, round(args.max_steps_s * rate))
                    start = time.perf_counter()
                    result = simulate(config, loop_trace)
                    records[rate] = result.records
                    metrics[rate] = (result.metrics, time.perf_counter() - start,
                                     sum(1 for r in result.records
                                         if not r.solver_success and r.av_speed_mps < 0.1))
                (one, _, _), (ten, wall, still) = metrics[1.0], metrics[args.rate_hz]
                ticks = ticks_per_model_step(1.0 / args.rate_hz, config.planner.dt_s)
                change = [step_change_rms_mps2(records[rate], t)
                          for rate, t in ((1.0, 1), (args.rate_hz, ticks))]
                by_age = explicability_by_age(records[args.rate_hz], ticks)
                print(f'| {trace} | {predictor} | {alpha:g} | {one.final_trust:.3f} / '
                      f'{ten.final_trust:.3f} ({rel(one.final_trust, ten.final_trust)}) | '
                      f'{one.mean_explicability:.5f} / {ten.mean_explicability:.5f} '
                      f'({rel(one.mean_explicability, ten.mean_explicability)}) | '
                      f'{one.rmse_mps2:.4f} / {ten.rmse_mps2:.4f} '
                      f'({rel(one.rmse_mps2, ten.rmse_mps2)}) | {ten.min_av_gap_m:.3f} | '
                      f'{ten.unsafe_steps} / {ten.fallback_steps} / {still} | '
                      f'{change[0]:.3f} / {change[1]:.3f} | {by_age[0]:.5f} / {by_age[-1]:.5f} | '
                      f'{wall:.0f} |',
                      flush=True)


if __name__ == '__main__':
    main()
