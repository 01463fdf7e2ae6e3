"""``trust-av train-gru``: build the TAC-CA dataset and train the GRU plan estimator.

The command re-runs itself in a child process with pinned numerics
(:mod:`~trust_av.study.pinned_numerics`); the training happens there.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import signal
import sys
import tempfile
import time
from pathlib import Path

from trust_av.cli.options import (
    MAX_ITERATIONS,
    MAX_SEED,
    Progress,
    bounded_int,
    output_file,
    params_files_option,
    positive_int,
)
from trust_av.cli.typed_options import add_command, option, trust_avs_option
from trust_av.errors import TrustAvAppError
from trust_av.graph import stop_signals
from trust_av.study.gru_training import TrainingSettings, save_model, train_with_dagger
from trust_av.study.pinned_numerics import (
    check_pinned,
    in_pinned_child,
    run_pinned,
    unsupported_reason,
)
from trust_av.system.config import load_run_config
from trust_av_planner.predictors.gru import MODELS_DIR

__all__: list[str] = []


def default_jobs() -> int:
    """Worker processes for the closed loops: the CPUs this process may use."""
    return len(os.sched_getaffinity(0))


@dataclasses.dataclass(frozen=True)
class TrainGruOptions:
    """``trust-av train-gru``'s options (``verbose``: trust-av's ``-v``, for the child)."""

    verbose: bool = trust_avs_option()
    out: Path = option('--out', default=MODELS_DIR / 'gru_plan_estimator.npz',
                       help='weights file to write (default: the shipped model)')
    epochs: int | None = option(
        '--epochs', type=bounded_int('--epochs', 1, MAX_ITERATIONS), default=None,
        help=f'override the epochs (1..{MAX_ITERATIONS})')
    seed: int | None = option('--seed', type=bounded_int('--seed', 0, MAX_SEED), default=None,
                              help=f'override the seed (0..{MAX_SEED})')
    dagger_rounds: int | None = option(
        '--dagger-rounds', type=bounded_int('--dagger-rounds', 0, MAX_ITERATIONS),
        default=None, help=lambda: 'override the number of DAgger rounds (default: '
                                   f'{TrainingSettings().dagger_rounds})')
    jobs: int | None = option(
        '--jobs', type=positive_int, default=None,
        help='processes for the closed-loop runs (default: the usable CPUs; '
             'the result does not depend on it)')
    params_files: tuple[Path, ...] = params_files_option()


def child_arguments(args: TrainGruOptions) -> list[str]:
    """The ``trust-av train-gru`` arguments that repeat ``args`` in the pinned child."""
    argv = ['-m', 'trust_av.cli', *(['-v'] if args.verbose else []), 'train-gru',
            '--out', os.path.abspath(args.out),
            *[arg for path in args.params_files
              for arg in ('--params-file', os.path.abspath(path))]]
    for flag, value in (('--epochs', args.epochs), ('--seed', args.seed),
                        ('--dagger-rounds', args.dagger_rounds), ('--jobs', args.jobs)):
        if value is not None:
            argv += [flag, str(value)]
    return argv


def settings_from_args(args: TrainGruOptions) -> TrainingSettings:
    """The shipped settings with the command line's overrides (checked)."""
    settings = TrainingSettings()
    if args.epochs is not None:
        if args.epochs < 1:
            raise TrustAvAppError(f'--epochs must be >= 1, got {args.epochs}')
        settings = dataclasses.replace(settings, epochs=args.epochs)
    if args.seed is not None:
        settings = dataclasses.replace(settings, seed=args.seed)
    if args.jobs is not None and args.jobs < 1:
        raise TrustAvAppError(f'--jobs must be >= 1, got {args.jobs}')
    if args.dagger_rounds is not None:
        if args.dagger_rounds < 0:
            raise TrustAvAppError(f'--dagger-rounds must be >= 0, got {args.dagger_rounds}')
        settings = dataclasses.replace(settings, dagger_rounds=args.dagger_rounds)
    return settings


def run(args: TrainGruOptions) -> int:
    """Run ``trust-av train-gru``: in a fresh process with pinned numerics (module
    :mod:`~.pinned_numerics`), which is this function again in the child."""
    config = load_run_config(args.params_files)
    settings = settings_from_args(args)
    output_file(args.out)             # before the training: minutes of work with nowhere to go
    for card in ('.json', '.png'):    # the model card and loss curve beside it
        output_file(args.out.with_suffix(card), '--out (its model card)')
    if not in_pinned_child():
        reason = unsupported_reason()
        if reason is not None:
            print(f'trust-av train-gru: warning: {reason}; training without the pinned CPU '
                  'kernels, so the model is not bit-comparable with the shipped one',
                  file=sys.stderr)
        code = run_pinned(child_arguments(args)).returncode
        if code < 0:   # killed: the child could not say why (the OOM killer sends SIGKILL)
            raise TrustAvAppError(f'the training process (pinned numerics) was killed by '
                                  f'{signal.Signals(-code).name}; nothing was written')
        return code
    check_pinned()
    start = time.monotonic()
    bar: Progress | None = None

    def stage(name: str) -> None:
        nonlocal bar
        if bar is not None:
            bar.close()
            bar = None
        print(f'[{time.monotonic() - start:6.1f} s] {name}', file=sys.stderr, flush=True)
        if name.startswith('training') or 'training on' in name:
            bar = Progress('  epochs', settings.epochs)

    def epoch(done: int, total: int) -> None:
        if bar is not None:
            bar.update(done, total)

    with tempfile.TemporaryDirectory() as work:
        weights, report = train_with_dagger(config, settings, Path(work), stage, epoch,
                                            jobs=args.jobs or default_jobs())
    if bar is not None:
        bar.close()
    stop_signals.deliver_pending(working=True)    # a stop is never followed by a write
    save_model(weights, report, settings, args.out)
    print(f"samples: {report['samples_train']} train, {report['samples_validation']} "
          'validation (last 20 % of every trace)')
    print(f"validation RMSE: GRU {report['validation_rmse_gru']:.4f} m/s^2, "
          f"CA {report['validation_rmse_ca']:.4f} m/s^2")
    print(f'wrote {args.out}, {args.out.with_suffix(".json")} (model card) and '
          f'{args.out.with_suffix(".png")} (loss curve) in {time.monotonic() - start:.1f} s')
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add ``train-gru`` to ``trust-av``."""
    parser = subparsers.add_parser(
        'train-gru', help='train the GRU plan estimator (TAC-GRU)',
        description='Run TAC-CA closed loops on the training traces (UDDS, HWFET, WLTC 3b) '
                    'for alpha in {0, 0.25, 0.5, 0.75, 1}, build 10 s histories -> next N '
                    'accelerations, train the GRU (seeded, deterministic, CPU), then two DAgger '
                    'rounds (TAC-GRU runs of the current model on the same traces are added '
                    'and the model retrained), then write the weights, a JSON model card and '
                    'the loss curve. Training runs in a child process with pinned CPU numerics: '
                    'the same machine gives the same weights bit for bit, machines like the one '
                    'the shipped model was trained on (AMD EPYC without AVX-512) give the '
                    'shipped weights bit for bit, other x86-64 CPUs with AVX2 weights within '
                    'about 1e-4 (docs/GRU.md). The default output replaces the shipped model.')
    add_command(parser, TrainGruOptions, run)
