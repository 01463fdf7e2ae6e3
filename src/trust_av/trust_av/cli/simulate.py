"""``trust-av simulate``: the in-process closed loop on one trace, with metrics and a CSV."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
from pathlib import Path

from preceding_traffic.traces import truncate
from trust_av.cli.options import (
    Progress,
    RunOptions,
    ceiling_at_end,
    collision_exit,
    format_metrics,
    output_file,
    positive_hz,
    steps_value,
)
from trust_av.cli.typed_options import add_command, option
from trust_av.system import run_record
from trust_av.system.closed_loop import SimResult, control_trace, simulate
from trust_av.system.config import load_run_config
from trust_av_common.component_checks import ComponentError
from trust_av_common.output_files import replacing
from trust_av_common.output_lock import hold_output_lock
from trust_av_planner.planner_params import check_control_rate

__all__: list[str] = []


@dataclasses.dataclass(frozen=True)
class SimulateOptions(RunOptions):
    """``trust-av simulate``'s options."""

    control_rate_hz: float | None = option(
        '--control-rate-hz', type=positive_hz, default=None,
        help='control rate: the trace is interpolated to it, the NMPC predicts '
             'on its period, trust is per second (default: 1 / dt_s, the '
             "paper's 1 Hz)")
    out: Path | None = option('--out', default=None,
                              help='write the per-step table (CSV) here')
    max_steps: int = option(
        '--max-steps', type=steps_value, default=0,
        help='stop after this many control steps (default: the whole trace); '
             "the steps equal the first ones of the whole trace's run")


def run(args: SimulateOptions) -> int:
    """Run ``trust-av simulate``."""
    if args.out is not None:
        output_file(args.out)
    config = load_run_config(args.params_files, args.overrides())
    if args.control_rate_hz is not None:  # the planner node's rule for control_rate_hz
        check_control_rate(config.planner, args.control_rate_hz)
    # --max-steps shortens the run only: the speed limit and the preview are the whole trace's
    trace = truncate(control_trace(config, args.control_rate_hz), args.max_steps)
    print(run_record.header(config), flush=True)
    with contextlib.ExitStack() as stack:
        if args.out is not None:   # a second command on --out is refused before it writes
            stack.enter_context(hold_output_lock(args.out))
        bar = Progress(f'simulate {trace.name}', trace.steps, shown=not args.no_progress)
        try:
            result = simulate(config, trace, on_step=bar.update)
        except ComponentError as err:   # the steps before it are kept in --out
            bar.close()
            if args.out is None or err.partial is None:
                raise
            write_table(err.partial, args.out)
            kept = len(err.partial.records)
            raise ComponentError(f'{err}; the {kept} step{"" if kept == 1 else "s"} before it '
                                 f'{"is" if kept == 1 else "are"} in {args.out}') from err
        bar.close()
        if args.out is not None:
            write_table(result, args.out)
    title = (f'TAC-{config.planner.predictor.upper()} on {trace.name}, '
             f'alpha = {config.planner.alpha:g} (in-process, {1.0 / trace.dt_s:g} Hz)')
    metrics = result.metrics
    print(format_metrics(metrics, title, trust_ceiling=ceiling_at_end(config, trace)))
    if args.out is not None:
        print(f'per-step table: {args.out}')
    return collision_exit(metrics, 'simulate')


def write_table(result: SimResult, out: Path) -> None:
    """Write the per-step table, whole or not at all (a temporary file beside ``out``).

    Raises:
        OutputFileError: the file cannot be written.
    """
    with replacing(out) as (temporary,):
        result.write_csv(temporary)


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add ``simulate`` to ``trust-av``."""
    parser = subparsers.add_parser(
        'simulate', help='in-process closed loop on one trace',
        description='Run the closed loop (traffic -> predictor -> AV NMPC -> trust -> human -> '
                    'integrate) in one process and print final trust, mean explicability, '
                    'prediction RMSE, minimum gaps and fallback counts. A gap at or below 0 m '
                    'is a collision: the run ends at that step, the summary says so and the '
                    'exit status is 3 (0 done, 2 bad input).')
    add_command(parser, SimulateOptions, run)
