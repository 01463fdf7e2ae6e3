"""``trust-av eval-driver``: score the shipped human driver on recorded car following."""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
from pathlib import Path

from human_driver_sim.car_following import CarFollowingDataError, LoadReport
from human_driver_sim.datasets import FORMATS, load_directory
from human_driver_sim.evaluation import (
    MIN_WINDOW_STEPS,
    PROTOCOLS,
    WINDOW_S,
    ConstantSpeed,
    Follower,
    IdmFollower,
    MpcFollower,
    evaluate,
    format_table,
)
from human_driver_sim.idm import TEXTBOOK_MOTORWAY, IdmParams
from human_driver_sim.ngsim import NGSIM_VEHICLE_LENGTH_M
from human_driver_sim.population import DRIVER_FIT_FILE, DriverFitError, fitted_idm_params
from trust_av.cli.options import output_file
from trust_av.cli.typed_options import add_command, option
from trust_av.errors import TrustAvAppError
from trust_av.system.config import (
    DEFAULT_PARAMS_FILE,
    HUMAN_CAUTIOUS_PARAMS_FILE,
    load_run_config,
)
from trust_av_common import output_files

__all__: list[str] = []

SHIPPED = 'driver MPC (params file)'
CAUTIOUS = 'driver MPC, cautious (human_cautious.yaml)'
BOUNDED_IDM = 'IDM, bounded fit'
TEXTBOOK_IDM = 'IDM, textbook motorway'
CONSTANT_SPEED = 'constant speed'
MAX_VEHICLE_LENGTH_M = 30.0
"""``--vehicle-length-m`` at most: longer than any road vehicle a chain could hold."""


@dataclasses.dataclass(frozen=True)
class EvalDriverOptions:
    """``trust-av eval-driver``'s options (one ``--params-file``, not layered)."""

    data: Path = option('--data', required=True, help='directory of CSV files')
    format: str | None = option('--format', choices=FORMATS, default=None,
                                help='file layout (default: detected from the first file)')
    json: Path | None = option('--json', default=None,
                               help='write pooled and per-pair scores to this JSON file')
    params_file: Path = option('--params-file', default=DEFAULT_PARAMS_FILE,
                               help='ROS 2 params file whose human_driver section is scored')
    driver_fit: Path = option(
        '--driver-fit', default=DRIVER_FIT_FILE,
        help='driver-fit file holding the bounded IDM (default: the shipped '
             "driver's fit, whose IDM is fitted on the training split)")
    window_s: float = option('--window-s', default=WINDOW_S,
                             help='re-initialised window length, s (default: %(default)s)')
    vehicle_length_m: float = option(
        '--vehicle-length-m', default=NGSIM_VEHICLE_LENGTH_M,
        help='NGSIM: assumed leader length, m (default: %(default)s)')


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the ``eval-driver`` subcommand."""
    parser = subparsers.add_parser(
        'eval-driver', help='score the shipped human driver on recorded car following',
        description=(
            "Score the params file's driver MPC, the same with the cautious profile "
            '(config/human_cautious.yaml) layered over it, the bounded IDM of the driver fit, the '
            'textbook IDM and constant speed on a directory of OpenACC or NGSIM-chain CSVs '
            '(read only): gap and speed NRMSE with 95 % CIs over pairs, collisions, gaps below '
            "2 m, beside the data's noise floor, for full runs and re-initialised windows."))
    add_command(parser, EvalDriverOptions, run)


def models(params_file: Path, driver_fit: Path) -> dict[str, Follower]:
    """The five scored models: the params file's driver, the same with the cautious profile
    layered over it, the bounded IDM of the driver fit, the textbook IDM and
    constant speed.

    Raises:
        TrustAvAppError: Bad driver-fit file (ParamsError propagates for a bad params file).
    """
    config = load_run_config(params_file).driver
    cautious = load_run_config([params_file, HUMAN_CAUTIOUS_PARAMS_FILE]).driver
    try:
        idm = IdmParams(**fitted_idm_params(driver_fit))
    except (DriverFitError, ValueError) as err:
        raise TrustAvAppError(str(err)) from err
    return {SHIPPED: MpcFollower(config), CAUTIOUS: MpcFollower(cautious),
            BOUNDED_IDM: IdmFollower(idm),
            TEXTBOOK_IDM: IdmFollower(TEXTBOOK_MOTORWAY), CONSTANT_SPEED: ConstantSpeed()}


def run(args: EvalDriverOptions) -> int:
    """Load, clean, score, print (and write JSON)."""
    if not (args.window_s > 0.0 and math.isfinite(args.window_s)):
        raise TrustAvAppError(f'--window-s must be > 0 and finite, got {args.window_s}')
    if not (math.isfinite(args.vehicle_length_m)
            and 0.0 <= args.vehicle_length_m <= MAX_VEHICLE_LENGTH_M):
        raise TrustAvAppError(f'--vehicle-length-m must be in [0, {MAX_VEHICLE_LENGTH_M:g}] '
                              f'm, got {args.vehicle_length_m}')
    if args.json is not None:
        output_file(args.json, '--json')
    scored = models(args.params_file, args.driver_fit)
    dt_s = load_run_config(args.params_file).driver.dt_s
    if args.window_s < MIN_WINDOW_STEPS * dt_s:
        raise TrustAvAppError(f'--window-s {args.window_s:g}: a window needs at least '
                              f'{MIN_WINDOW_STEPS} steps of dt_s = {dt_s:g} s '
                              f'({MIN_WINDOW_STEPS * dt_s:g} s)')
    report = LoadReport()
    try:
        pairs = load_directory(args.data, args.format, report=report, dt_s=dt_s,
                               vehicle_length_m=args.vehicle_length_m)
    except CarFollowingDataError as err:
        raise TrustAvAppError(str(err)) from err
    result = evaluate(scored, pairs, window_s=args.window_s)
    print(f'{args.data}: {len(report.files)} files, {len(result.pairs)} pairs '
          f'({len(pairs)} segments); splices cut: {len(report.splices)}; '
          f'repeated windows merged: {report.duplicates_merged}; left out: '
          f'{len(report.excluded)}')
    for splice in report.splices:
        print(f'  splice {splice.pair}: {splice.start_s:.1f}-{splice.end_s:.1f} s cut '
              f'(gap rate vs Doppler up to {splice.max_residual_mps:.1f} m/s)')
    for key, why in report.excluded.items():
        print(f'  left out {key}: {why}')
    for protocol in PROTOCOLS:
        print()
        print(format_table(result, protocol))
    if args.json is not None:
        document = {'data': str(args.data), 'files': report.files,
                    'splices': [vars(s) for s in report.splices],
                    'excluded': report.excluded, 'window_s': args.window_s,
                    'vehicle_length_m': report.vehicle_length_m, **result.to_dict()}
        output_files.write_text(args.json, json.dumps(document, indent=1))
        print(f'\nwrote {args.json}')
    return 0
