"""``trust-av fit-driver``: fit the driver MPC (W, tau_H, d_s, caution) to human car following."""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import math
import subprocess
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from human_driver_sim import irl
from human_driver_sim.car_following import CarFollowingDataError, LoadReport
from human_driver_sim.datasets import load_directory
from human_driver_sim.driver_mpc import DriverConfig
from human_driver_sim.evaluation import (
    ConstantSpeed,
    Evaluation,
    Follower,
    IdmFollower,
    MpcFollower,
    evaluate,
    format_table,
    make_runs,
    paired_difference,
)
from human_driver_sim.fitting import MPC_BOUNDS, FitResult, configured, fit_idm, fit_mpc
from human_driver_sim.idm import PARAM_NAMES, TEXTBOOK_MOTORWAY, IdmParams
from human_driver_sim.population import DRIVER_FIT_FILE, WEIGHT_NAMES
from human_driver_sim.splits import Split, split_ngsim, split_openacc
from trust_av.cli.options import MAX_ITERATIONS, Progress, bounded_int, output_file
from trust_av.cli.typed_options import add_command, option
from trust_av.errors import TrustAvAppError
from trust_av.graph import stop_signals
from trust_av.system.config import (
    DEFAULT_PARAMS_FILE,
    HUMAN_CAUTIOUS_PARAMS_FILE,
    load_run_config,
)
from trust_av_common.output_files import replacing

__all__: list[str] = []

TARGET_RATIO = 0.9
"""The target: the driver's test gap NRMSE at most 0.9 x the best IDM's."""
MPC_NAMES = tuple(MPC_BOUNDS)
CANDIDATES: dict[str, dict[str, Any]] = {
    'MPC fitted caution': {'cautious': False},
}
"""Driver-MPC candidates fitted on the training split; the validation split picks one of
them, :data:`ABLATION` and the cautious driver, :data:`CAUTIOUS_MPC` (the params file's
driver with the profile config/human_cautious.yaml layered over it). The cautious driver is not
refitted (its fit binds the gap bound on many NGSIM steps and takes most of the time): it was
fitted on part2 and the even NGSIM IDs, training and validation together, so its validation
score is if anything optimistic."""
ABLATION = 'MPC fitted caution, a_extra = 0'
"""The fitted-caution driver with its caution removed (the bound against min(u_R^H, 0))."""
CAUTIOUS_MPC = 'MPC cautious (human_cautious.yaml)'
IDM_POOLED = 'IDM pooled (bounded)'
IDM_TEXTBOOK = 'IDM textbook'


@dataclasses.dataclass(frozen=True)
class FitDriverOptions:
    """``trust-av fit-driver``'s options (one ``--params-file``, not layered)."""

    data: Path = option('--data', required=True,
                        help='OpenACC Vicolungo directory: part2 trains and validates, part3 '
                             'is the test set (read only, never copied)')
    ngsim: Path | None = option(
        '--ngsim', default=None,
        help='NGSIM I-80 chain directory: split by follower ID (optional)')
    drives: Path | None = option(
        '--drives', default=None,
        help='a trust-av drive study directory: its complete drives (a person '
             'following the AV) are demonstrations too, split by participant '
             'into train, validation and test like NGSIM (optional)')
    out: Path = option(
        '--out', default=DRIVER_FIT_FILE,
        help='fit file with provenance (default: '
             'human_driver_sim/models/driver_fit_caution.yaml, whose pooled fit '
             "is config/trust_av.yaml's driver); its evaluation is written "
             'beside it as <stem>_eval.json')
    params_file: Path = option(
        '--params-file', default=DEFAULT_PARAMS_FILE,
        help='ROS 2 params file whose human_driver section gives what is '
             'not fitted (dt_s, horizon, bounds); with config/human_cautious.yaml '
             'layered over it, the cautious candidate (default: the shipped)')
    iterations: int = option(
        '--iterations', type=bounded_int('--iterations', 1, MAX_ITERATIONS), default=70,
        help='Nelder-Mead iterations per start (default: %(default)s, the shipped fit)')
    no_progress: bool = option('--no-progress', help='no progress bar')


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the ``fit-driver`` subcommand."""
    parser = subparsers.add_parser(
        'fit-driver', help='fit the driver MPC (W, tau_H, d_s, caution) to human car following',
        description=(
            'Fit the human driver MPC (weights W, time headway tau_H, standstill gap d_s; '
            'cautious, or with a fitted caution a_extra) and a bounded IDM on a training split '
            'of OpenACC car following (part2, first 70 %%) and optionally NGSIM chains (follower '
            'ID 0 mod 4), pick the driver candidate on the validation split (the rest of part2; '
            'NGSIM 2 mod 4), score every model once on the test split (part3; odd NGSIM IDs) '
            'against the IDMs, constant speed and the noise floor, and write the fit with its '
            'provenance and the evaluation beside it. The data are read from their paths, never '
            'copied.'))
    add_command(parser, FitDriverOptions, run)


def _code_version() -> str:
    try:
        out = subprocess.run(['git', 'rev-parse', '--short', 'HEAD'], capture_output=True,
                             text=True, check=True, cwd=Path(__file__).parent)
        return out.stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return 'unknown'


def _mpc_starts(kkt: np.ndarray) -> list[dict[str, float]]:
    """Three fixed starts (the fit depends on the data only, not on the params file): the
    inverse-KKT W at tau_H = 1.5 s, and two spread points of the box."""
    floor = {n: MPC_BOUNDS[n][0] * 1.01 for n in MPC_NAMES}
    from_kkt = {'weight_desired_speed': max(float(kkt[1]), floor['weight_desired_speed']),
                'weight_relative_speed': max(float(kkt[2]), floor['weight_relative_speed']),
                'weight_relative_distance': max(float(kkt[3]),
                                                floor['weight_relative_distance']),
                'time_headway_s': 1.5, 'desired_standstill_gap_m': 6.0}
    return [from_kkt,
            {'weight_desired_speed': 1e-3, 'weight_relative_speed': 0.15,
             'weight_relative_distance': 2e-3, 'time_headway_s': 1.2,
             'desired_standstill_gap_m': 5.5},
            {'weight_desired_speed': 1e-4, 'weight_relative_speed': 0.05,
             'weight_relative_distance': 0.01, 'time_headway_s': 1.0,
             'desired_standstill_gap_m': 8.0}]


def compact(value: Any) -> Any:
    """``value`` with every float rounded to 6 significant digits (a smaller JSON)."""
    if isinstance(value, float):
        return float(f'{value:.6g}')
    if isinstance(value, dict):
        return {k: compact(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [compact(v) for v in value]
    return value


def _load(args: FitDriverOptions, dt_s: float) -> tuple[dict[str, Split], dict[str, Any]]:
    """Train / validation / test pairs per data set, and what cleaning did."""
    cleaning: dict[str, Any] = {}
    splits: dict[str, Split] = {}
    try:
        report = LoadReport()
        splits['openacc'] = split_openacc(load_directory(args.data, 'openacc', dt_s=dt_s,
                                                         report=report))
        cleaning['openacc'] = {'files': [Path(f).name for f in report.files],
                               'splices': [vars(s) for s in report.splices]}
        if args.ngsim is not None:
            report = LoadReport()
            splits['ngsim'] = split_ngsim(load_directory(args.ngsim, 'ngsim', dt_s=dt_s,
                                                         report=report))
            cleaning['ngsim'] = {'files': len(report.files), 'excluded': report.excluded,
                                 'duplicates_merged': report.duplicates_merged,
                                 'vehicle_length_m': report.vehicle_length_m}
    except CarFollowingDataError as err:
        raise TrustAvAppError(f'{args.data}: {err}') from err
    if args.drives is not None:          # driver-in-the-loop demonstrations
        from trust_av.drive.bag_data import drive_bag_pairs
        splits['drive'], cleaning['drive'] = drive_bag_pairs(
            args.drives, dt_s, load_run_config(args.params_file).shared.vehicle_length_m)
    for name, split in splits.items():
        for role, pairs in split._asdict().items():
            if not pairs:
                raise TrustAvAppError(f'no {name} pairs left for the {role} split')
    return splits, cleaning


def _validation_loss(follower: Follower, splits: Mapping[str, Split]) -> dict[str, float]:
    """The fitting loss on the validation split, per data set and their mean."""
    out = {name: float(np.mean([s.gap_nrmse for s in evaluate(
        {'m': follower}, split.validation, protocols=('window',)).per_pair['window']['m']
        .values()])) for name, split in splits.items()}
    out['mean'] = float(np.mean(list(out.values())))
    return out


def _target(evaluation: Evaluation, protocol: str, model: str,
            idm_models: Sequence[str]) -> dict[str, Any]:
    """The selected MPC against the best IDM (lowest test gap NRMSE) of one protocol, with
    the paired difference over pairs (MPC - IDM, mean and 95 % CI half-width)."""
    mpc = evaluation.pooled(protocol, model)
    best = min(idm_models, key=lambda m: evaluation.pooled(protocol, m)['gap_nrmse'])
    idm = evaluation.pooled(protocol, best)
    ratio = mpc['gap_nrmse'] / idm['gap_nrmse']
    diff = paired_difference(evaluation, protocol, model, best)
    return {'model': model, 'mpc_gap_nrmse': mpc['gap_nrmse'],
            'mpc_ci95': mpc['gap_nrmse_ci95'], 'best_idm': best,
            'idm_gap_nrmse': idm['gap_nrmse'], 'idm_ci95': idm['gap_nrmse_ci95'],
            'ratio': ratio, 'paired_difference': diff, 'met': bool(ratio <= TARGET_RATIO),
            'mpc_collisions': mpc['collisions'], 'mpc_steps_below_2m': mpc['steps_below_2m'],
            'mpc_min_gap_m': mpc['min_gap_m']}


def run(args: FitDriverOptions) -> int:
    """Fit on train, select on validation, score once on test, write the fit and evaluation."""
    started = time.perf_counter()
    if args.iterations < 1:
        raise TrustAvAppError(f'--iterations must be >= 1, got {args.iterations}')
    output_file(args.out)             # before the fit: minutes of work with nowhere to go
    output_file(args.out.with_name(args.out.stem + '_eval.json'), '--out (its evaluation)')
    # the cautious driver: the candidate that is not refitted, and the inverse-KKT start's tau_H
    # and d_s (so the fit does not move with the params file's fitted driver)
    base = load_run_config([args.params_file, HUMAN_CAUTIOUS_PARAMS_FILE]).driver
    splits, cleaning = _load(args, base.dt_s)
    n = base.horizon_steps
    train = {name: make_runs(split.train, 'window') for name, split in splits.items()}
    kkt = irl.fit_inverse_kkt(base, [d for p in splits['openacc'].train
                                     for d in irl.demonstrations(p, n)])
    starts = _mpc_starts(kkt)
    drivers = sorted({p.driver for p in splits['openacc'].train})
    bar = Progress('fit-driver', (len(CANDIDATES) * len(starts) + 3 + len(drivers))
                   * int(1.5 * args.iterations + 7), shown=not args.no_progress)
    fits: dict[str, FitResult] = {}
    seconds: dict[str, float] = {}
    for name, changes in CANDIDATES.items():
        clock = time.perf_counter()
        fits[name] = fit_mpc(dataclasses.replace(base, **changes), list(train.values()),
                             starts=starts, iterations=args.iterations, progress=bar.update)
        seconds[name] = time.perf_counter() - clock
    clock = time.perf_counter()
    idm = fit_idm(list(train.values()), iterations=args.iterations, progress=bar.update)
    seconds[IDM_POOLED] = time.perf_counter() - clock
    candidates = {name: configured(dataclasses.replace(base, **CANDIDATES[name]),
                                   fits[name].params) for name in CANDIDATES}
    candidates[ABLATION] = dataclasses.replace(candidates['MPC fitted caution'],
                                               av_extra_decel_mps2=0.0)
    candidates[CAUTIOUS_MPC] = base
    validation = {name: _validation_loss(MpcFollower(cfg), splits)
                  for name, cfg in candidates.items()}
    for name, follower in ((IDM_POOLED, IdmFollower(IdmParams(**idm.params))),
                           (IDM_TEXTBOOK, IdmFollower(TEXTBOOK_MOTORWAY))):
        validation[name] = _validation_loss(follower, splits)
    selected = min(candidates, key=lambda m: validation[m]['mean'])
    chosen = candidates[selected]
    chosen_params = {k: float(getattr(chosen, k)) for k in (*MPC_NAMES,
                                                             'av_extra_decel_mps2')}
    per_driver: dict[str, dict[str, float]] = {}
    for driver in drivers:
        clock = time.perf_counter()
        own = fit_mpc(chosen, [make_runs([p for p in splits['openacc'].train
                                          if p.driver == driver], 'window')],
                      starts=[chosen_params], iterations=args.iterations,
                      progress=bar.update)
        seconds[f'driver {driver}'] = time.perf_counter() - clock
        per_driver[driver] = {'weight_acceleration': 1.0, **own.params}
        fits[f'driver {driver}'] = own
    bar.close()
    per_pair = {p.key: irl.fit_inverse_kkt(chosen, irl.demonstrations(p, n))
                for p in splits['openacc'].train}
    models: dict[str, Follower] = {name: MpcFollower(cfg) for name, cfg in candidates.items()}
    models[IDM_POOLED] = IdmFollower(IdmParams(**idm.params))
    models[IDM_TEXTBOOK] = IdmFollower(TEXTBOOK_MOTORWAY)
    models['constant speed'] = ConstantSpeed()
    # The test split, scored once.
    tests = {f'{name} test': evaluate(models, split.test) for name, split in splits.items()}
    targets = {name: {protocol: _target(ev, protocol, selected, (IDM_POOLED, IDM_TEXTBOOK))
                      for protocol in ('full', 'window')} for name, ev in tests.items()}
    fit_time_s = time.perf_counter() - started
    document = {
        'provenance': _provenance(args, base, fit_time_s),
        'selected': selected,
        'pooled': {'weight_acceleration': 1.0, **chosen_params, 'cautious': chosen.cautious},
        'fit_loss': fits[selected].loss if selected in fits else None,
        'validation_loss': validation,
        'mpc_starts': starts,
        'per_driver': per_driver,
        'pooled_inverse_kkt': {k: float(v) for k, v in zip(WEIGHT_NAMES, kkt, strict=True)},
        'per_pair_inverse_kkt': {name: [float(x) for x in w] for name, w in per_pair.items()},
        'fits': {name: {'params': {'weight_acceleration': 1.0, **f.params}, 'loss': f.loss,
                        'start_losses': f.start_losses, 'seconds': round(seconds[name], 1)}
                 for name, f in fits.items()},
        'idm': {k: float(idm.params[k]) for k in PARAM_NAMES},
        'idm_loss': idm.loss, 'idm_start_losses': idm.start_losses,
        'idm_textbook': {k: float(getattr(TEXTBOOK_MOTORWAY, k)) for k in PARAM_NAMES},
        'target': targets}
    eval_path = args.out.with_name(args.out.stem + '_eval.json')
    stop_signals.deliver_pending(working=True)    # a stop is never followed by a write
    with replacing(args.out, eval_path) as (fit_file, eval_file):  # both or neither
        fit_file.write_text(yaml.safe_dump(document, sort_keys=False))
        eval_file.write_text(json.dumps(compact({
            'cleaning': cleaning, 'split_pairs': {
                name: {role: sorted({p.key for p in pairs})
                       for role, pairs in split._asdict().items()}
                for name, split in splits.items()},
            'selected': selected, 'validation_loss': validation, 'target': targets,
            'sets': {k: v.to_dict() for k, v in tests.items()}}), indent=1))
    _report(validation, selected, tests, targets)
    print(f'selected: {document["pooled"]}; fit time {fit_time_s:.1f} s; wrote {args.out} '
          f'and {eval_path}')
    return 0


def _provenance(args: FitDriverOptions, base: DriverConfig, fit_time_s: float) -> dict[str, Any]:
    """Where the fit comes from: data, split, licence, method, and this run."""
    return {
        'data': [args.data.name] + ([args.ngsim.name] if args.ngsim is not None else []),
        'split': 'OpenACC: part2 first 70 % of each segment train, the rest validation, '
                 'part3 test; NGSIM by follower ID: 0 mod 4 train, 2 mod 4 validation, '
                 'odd test. Candidates and the IDM fitted on train, the model selected '
                 'on validation, test scored once',
        'licence': 'JRC OpenACC database, CC BY 4.0, (c) European Union; NGSIM I-80, US '
                   'DOT FHWA (public), chains from Keke-Long/PERL_planning (Apache-2.0). '
                   'Changed: speeds from GNSS along-track positions, splices cut, '
                   'resampled to dt_s; NGSIM windows merged, 4.5 m leaders assumed',
        'method': 'bounded multi-start Nelder-Mead on the mean window (30 s) gap NRMSE, '
                  'averaged over data sets, of W, tau_H, the desired standstill gap d_s '
                  'and (not cautious) the caution a_extra (w_a = 1); IDM fitted the same '
                  'way inside physical bounds; per-driver fits of the selected model from '
                  'the pooled one (population); per-pair inverse KKT at the selected model',
        'expected_leader_plan': 'constant acceleration at the last observed one',
        'integrator': 'explicit Euler (longitudinal.step), as the MPC and the simulator',
        'dt_s': base.dt_s, 'horizon_steps': base.horizon_steps,
        'date': datetime.datetime.now(datetime.UTC).isoformat(timespec='seconds'),
        'code_version': _code_version(), 'fit_time_s': round(fit_time_s, 1),
        'iterations': args.iterations}


def _report(validation: dict[str, dict[str, float]], selected: str,
            tests: dict[str, Any], targets: dict[str, dict[str, dict[str, Any]]]) -> None:
    """Print the validation losses, the selection, the test tables and the targets."""
    for name, losses in validation.items():
        print(f'validation {name}: ' + ', '.join(f'{k} {v:.4f}' for k, v in losses.items()))
    print(f'selected on validation: {selected}')
    for name, evaluation in tests.items():
        for protocol in ('full', 'window'):
            print(f'\n{name}, ' + format_table(evaluation, protocol))
    for name, by_protocol in targets.items():
        for protocol, t in by_protocol.items():
            d = t['paired_difference']
            print(f'target {name} {protocol}: {selected} {t["mpc_gap_nrmse"]:.3f} / '
                  f'{t["best_idm"]} {t["idm_gap_nrmse"]:.3f} = {t["ratio"]:.3f} '
                  f'({"met" if t["met"] else "not met"}, <= {TARGET_RATIO}); paired '
                  f'difference {d["mean"]:+.3f} ± {d["ci95"]:.3f} (MPC better on '
                  f'{d["better"]} of {d["pairs"]}); {platoon_interval(d)}')


def platoon_interval(difference: dict[str, Any]) -> str:
    """The cluster-bootstrap interval of a paired difference, in words."""
    low, high = difference['cluster_ci95']
    if math.isnan(low):
        return f'{difference["platoons"]} platoon: no cluster interval'
    return (f'cluster bootstrap over {difference["platoons"]} platoons '
            f'[{low:+.3f}, {high:+.3f}]')
