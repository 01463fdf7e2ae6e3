"""``trust-av fit-driver``: fit the driver MPC's weights W (eq. 13) to human car following."""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import subprocess
import time
from pathlib import Path

import numpy as np
import yaml

from human_driver_sim import irl
from human_driver_sim.car_following import CarFollowingDataError, FollowingPair, read_openacc
from human_driver_sim.idm import IdmParams, replay
from human_driver_sim.population import DRIVER_FIT_FILE
from trust_av_planner.cli.options import Progress
from trust_av_planner.errors import TrustAvPlannerError
from trust_av_planner.system.config import DEFAULT_PARAMS_FILE, load_run_config

FIT_FILE = 'JRC-VC_280219_part2.csv'
TEST_FILE = 'JRC-VC_280219_part3.csv'
IDM_NAMES = ('desired_speed_mps', 'time_headway_s', 'min_gap_m', 'max_accel_mps2',
             'comfort_decel_mps2')


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the ``fit-driver`` subcommand."""
    parser = subparsers.add_parser('fit-driver', help=__doc__)
    parser.add_argument('--data', type=Path, required=True,
                        help='OpenACC Vicolungo directory (read only, never copied)')
    parser.add_argument('--out', type=Path, default=DRIVER_FIT_FILE,
                        help='weights file with provenance (default: the shipped fit, '
                             'human_driver_sim/models/driver_fit.yaml)')
    parser.add_argument('--params-file', type=Path, default=DEFAULT_PARAMS_FILE)
    parser.add_argument('--iterations', type=int, default=40,
                        help='Nelder-Mead iterations of the bilevel refinement (default: '
                             '%(default)s)')
    parser.add_argument('--no-progress', action='store_true')
    parser.set_defaults(func=run)


def _idm(logs: np.ndarray) -> IdmParams:
    return IdmParams(*(float(x) for x in np.exp(logs)))


def fit_idm(pairs: list[FollowingPair]) -> tuple[IdmParams, float]:
    """IDM's 5 parameters minimising mean replay gap RMSE (Nelder-Mead on their logs)."""
    def loss(logs: np.ndarray) -> float:
        params = _idm(logs)
        return float(np.mean([irl.rmse(replay(params, p.leader_speed_mps, p.gap_m[0],
                                                  p.follower_speed_mps[0], p.dt_s)[0], p.gap_m)
                              for p in pairs]))
    start = np.log([33.0, 1.5, 2.0, 1.0, 1.5])
    logs, value = irl.nelder_mead(loss, start, step=0.3, iterations=300)
    return _idm(logs), value


def _code_version() -> str:
    try:
        out = subprocess.run(['git', 'rev-parse', '--short', 'HEAD'], capture_output=True,
                             text=True, check=True, cwd=Path(__file__).parent)
        return out.stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return 'unknown'


def run(args: argparse.Namespace) -> int:
    """Fit, evaluate on the held-out part, write the weights file."""
    started = time.perf_counter()
    config = load_run_config(args.params_file).driver
    try:
        fit_pairs = read_openacc(args.data / FIT_FILE, dt_s=config.dt_s)
        test_pairs = read_openacc(args.data / TEST_FILE, dt_s=config.dt_s)
    except CarFollowingDataError as err:
        raise TrustAvPlannerError(str(err)) from err
    n = config.horizon_steps
    kkt = irl.fit_inverse_kkt(config, [d for p in fit_pairs for d in irl.demonstrations(p, n)])
    bar = None if args.no_progress else Progress('fit-driver', 2 * (args.iterations * 2 + 5))
    update = None if bar is None else bar.update
    candidates = [irl.refine_bilevel(config, fit_pairs, start, iterations=args.iterations,
                                     progress=update)
                  for start in (kkt, config.weights / config.weight_acceleration)]
    pooled, time_headway_s, fit_gap = min(candidates, key=lambda c: c[2])
    if bar is not None:
        bar.close()
    fitted = dataclasses.replace(irl.with_weights(config, pooled), time_headway_s=time_headway_s)
    # Per-pair weights (the population source) at the fitted time headway.
    per_pair = {p.name: irl.fit_inverse_kkt(fitted, irl.demonstrations(p, n)) for p in fit_pairs}
    idm, idm_fit_gap = fit_idm(fit_pairs)
    evaluation = {}
    for p in test_pairs:
        gap, speed = irl.replay_mpc(fitted, p)
        igap, ispeed = replay(idm, p.leader_speed_mps, p.gap_m[0], p.follower_speed_mps[0],
                              p.dt_s)
        evaluation[p.name] = {
            'driver_mpc_gap_rmse_m': irl.rmse(gap, p.gap_m),
            'driver_mpc_speed_rmse_mps': irl.rmse(speed, p.follower_speed_mps),
            'idm_gap_rmse_m': irl.rmse(igap, p.gap_m),
            'idm_speed_rmse_mps': irl.rmse(ispeed, p.follower_speed_mps)}
    names = ('weight_acceleration', 'weight_desired_speed', 'weight_relative_speed',
             'weight_relative_distance')
    result = {
        'provenance': {
            'data': [str(args.data / FIT_FILE), str(args.data / TEST_FILE) + ' (held out)'],
            'licence': 'JRC OpenACC database, CC BY 4.0, (c) European Union; resampled from '
                       '10 Hz to dt_s by linear interpolation, speeds and IVS gaps only',
            'method': 'inverse KKT (Keshavarz et al. 2011; Englert et al. 2017), w_a = 1, '
                      'then bilevel Nelder-Mead on open-loop replay gap RMSE over W and the '
                      'time headway tau_H; per-pair inverse KKT at the fitted tau_H',
            'expected_leader_plan': 'constant acceleration at the last observed one',
            'dt_s': config.dt_s, 'horizon_steps': n,
            'date': datetime.datetime.now(datetime.UTC).isoformat(timespec='seconds'),
            'code_version': _code_version(),
            'fit_time_s': round(time.perf_counter() - started, 1)},
        'pooled': {**{k: float(v) for k, v in zip(names, pooled, strict=True)},
                   'time_headway_s': float(time_headway_s)},
        'pooled_inverse_kkt': {k: float(v) for k, v in zip(names, kkt, strict=True)},
        'fit_gap_rmse_m': fit_gap,
        'per_pair_inverse_kkt': {name: [float(x) for x in w] for name, w in per_pair.items()},
        'idm': {k: float(getattr(idm, k)) for k in IDM_NAMES},
        'idm_fit_gap_rmse_m': idm_fit_gap,
        'held_out': evaluation}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(yaml.safe_dump(result, sort_keys=False))
    for name, row in evaluation.items():
        print(name, ' '.join(f'{k}={v:.2f}' for k, v in row.items()))
    mean = {k: float(np.mean([row[k] for row in evaluation.values()]))
            for k in next(iter(evaluation.values()))}
    print('held-out mean: ' + ' '.join(f'{k}={v:.2f}' for k, v in mean.items()))
    print(f'pooled W = {pooled}, tau_H = {time_headway_s:.3f} s; wrote {args.out}')
    return 0
