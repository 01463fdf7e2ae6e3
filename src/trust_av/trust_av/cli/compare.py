"""``trust-av compare``: two runs side by side in one figure
(:mod:`trust_av.study.compare_runs`)."""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from trust_av.cli.options import output_file, params_files_option
from trust_av.cli.typed_options import add_command, option, positional
from trust_av_common import registry
from trust_monitor.model_interface import TRUST_MODELS

__all__ = ['CompareOptions', 'register']


def two_labels(text: str) -> list[str]:
    """argparse type: two comma-separated names."""
    names = [t.strip() for t in text.split(',')]
    if len(names) != 2 or not all(names):
        raise argparse.ArgumentTypeError(f'{text!r}: give two names, NAME_A,NAME_B')
    return names


@dataclasses.dataclass(frozen=True)
class CompareOptions:
    """``trust-av compare``'s options."""

    run_a: Path = positional(
        metavar='RUN_A', help='the first run: a bag directory, its .mcap, or a simulate CSV')
    run_b: Path = positional(metavar='RUN_B', help='the second run, the same')
    out: Path = option('--out', required=True, help='the figure to write: .png, .pdf or .svg')
    trust_models: str = option(
        '--trust-models', default='',
        help=lambda: 'comma-separated registered trust models to draw '
                     f'({", ".join(registry.names(TRUST_MODELS))}; default: all)')
    labels: tuple[str, ...] | None = option(
        '--labels', type=two_labels, default=None, metavar='NAME_A,NAME_B',
        help="the runs' names in the figure (default: their file names)")
    params_files: tuple[Path, ...] = params_files_option()


def run(args: CompareOptions) -> int:
    """Run ``trust-av compare``."""
    from trust_av.study.compare_runs import compare_runs  # matplotlib when drawing

    output_file(args.out)                          # before any run is read
    final = compare_runs(args.run_a, args.run_b, args.out,
                         models=[m.strip() for m in args.trust_models.split(',')]
                         if args.trust_models else None,
                         params_files=list(args.params_files),
                         labels=list(args.labels) if args.labels else None)
    for name, models in final.items():
        print(f'{name}: final trust (common scale) '
              + ', '.join(f'{m} {v:.3f}' for m, v in models.items()))
    print(f'figure: {args.out}')
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add ``compare`` to ``trust-av``."""
    parser = subparsers.add_parser(
        'compare', help='draw two runs side by side (speeds, gaps, accelerations, E, trust '
                        'per model)',
        description='Draw two runs side by side in one figure, a column per run, a row per '
                    'quantity on one scale: speeds (traffic, AV, human), gaps, '
                    'accelerations, explicability E, and the trust of every trust model run '
                    "over the run's E, on the common scale [0, 1]. A run is a rosbag2 "
                    'recording (trust-av run --bag DIR, reproduce --graph, a trust-av drive '
                    "study's drive: the directory or its .mcap) or a per-step CSV (trust-av "
                    'simulate --out FILE). Prints each '
                    "model's final trust per run. Bad input: one line, exit 2.")
    add_command(parser, CompareOptions, run)
