"""``trust-av simulate``: the in-process closed loop on one trace, with metrics and a CSV."""

from __future__ import annotations

import argparse
from pathlib import Path

from preceding_traffic.traces import SHIPPED_TRACES, load_trace
from trust_av_planner.config import DEFAULT_PARAMS_FILE, load_run_config
from trust_av_planner.nmpc import PREDICTORS
from trust_av_planner.progress import ProgressBar
from trust_av_planner.simulate import Metrics, simulate


def alpha_value(text: str) -> float:
    """argparse type for alpha: a number in [0, 1]."""
    try:
        value = float(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(f'alpha must be a number, got {text!r}') from err
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f'alpha must be in [0, 1], got {value}')
    return value


def add_params_file_option(parser: argparse.ArgumentParser) -> None:
    """``--params-file``, defaulting to the shipped config/trust_av.yaml."""
    parser.add_argument('--params-file', type=Path, default=DEFAULT_PARAMS_FILE,
                        help='ROS 2 params file (default: %(default)s)')


def add_run_options(parser: argparse.ArgumentParser) -> None:
    """Options shared by the commands that run one closed loop."""
    source = parser.add_mutually_exclusive_group()
    source.add_argument('--trace', default=None,
                        help=f'preceding-traffic trace: one of {", ".join(SHIPPED_TRACES)}, a '
                             'time_s,speed_mps CSV or a rosbag2 bag '
                             "(default: the params file's preceding_traffic.trace)")
    source.add_argument('--bag-in', type=Path, default=None, metavar='BAG',
                        help='replay a rosbag2 bag (MCAP or sqlite3 directory or file) as the '
                             'preceding vehicle; the same as --trace BAG')
    parser.add_argument('--bag-topic', default=None,
                        help="the preceding vehicle's topic in the bag (default: the params "
                             "file's preceding_traffic.bag_topic)")
    parser.add_argument('--bag-type', default=None,
                        choices=('nav_msgs/msg/Odometry', 'geometry_msgs/msg/TwistStamped'),
                        help='its message type (default: preceding_traffic.bag_message_type)')
    parser.add_argument('--alpha', type=alpha_value, default=None,
                        help="explicability weight in [0, 1] (default: the params file's)")
    parser.add_argument('--predictor', choices=PREDICTORS, default=None,
                        help='estimator of the plan the human expects (default: params file)')
    add_params_file_option(parser)
    parser.add_argument('--no-progress', action='store_true', help='no progress bar')


def run_overrides(args: argparse.Namespace) -> dict[str, dict[str, object]]:
    """Params-file overrides from the command-line options."""
    planner: dict[str, object] = {}
    if args.alpha is not None:
        planner['alpha'] = args.alpha
    if args.predictor is not None:
        planner['predictor'] = args.predictor
    traffic: dict[str, object] = {}
    if args.trace is not None:
        traffic['trace'] = args.trace
    if args.bag_in is not None:
        traffic['trace'] = str(args.bag_in)
    if args.bag_topic is not None:
        traffic['bag_topic'] = args.bag_topic
    if args.bag_type is not None:
        traffic['bag_message_type'] = args.bag_type
    return {'planner': planner, 'preceding_traffic': traffic}


def format_metrics(metrics: Metrics, title: str) -> str:
    """The metrics table printed at the end of a run."""
    rows = [('steps', f'{metrics.steps}'),
            ('final trust', f'{metrics.final_trust:.3f}'),
            ('mean explicability E', f'{metrics.mean_explicability:.5f}'),
            ('prediction RMSE (m/s^2)', f'{metrics.rmse_mps2:.4f}'),
            ('min AV gap (m)', f'{metrics.min_av_gap_m:.3f}'),
            ('min human gap (m)', f'{metrics.min_human_gap_m:.3f}'),
            ('NMPC fallback steps', f'{metrics.fallback_steps}'),
            ('driver fallback steps', f'{metrics.driver_fallback_steps}'),
            ('unsafe steps (gap < d_s - margin)', f'{metrics.unsafe_steps}')]
    width = max(len(k) for k, _ in rows)
    lines = [title, '-' * (width + 14)]
    lines += [f'{k:<{width}}  {v:>12}' for k, v in rows]
    return '\n'.join(lines)


def run(args: argparse.Namespace) -> int:
    """Run ``trust-av simulate``."""
    config = load_run_config(args.params_file, run_overrides(args))
    trace = load_trace(config.trace.trace, config.planner.dt_s, config.trace)
    bar = None if args.no_progress else ProgressBar(f'simulate {trace.name}', trace.steps)
    result = simulate(config, trace, on_step=None if bar is None else bar.update)
    if bar is not None:
        bar.close()
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        result.write_csv(args.out)
    title = (f'TAC-{config.planner.predictor.upper()} on {trace.name}, '
             f'alpha = {config.planner.alpha:g} (in-process)')
    print(format_metrics(result.metrics, title))
    if args.out is not None:
        print(f'per-step table: {args.out}')
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add ``simulate`` to ``trust-av``."""
    parser = subparsers.add_parser(
        'simulate', help='in-process closed loop on one trace',
        description='Run the closed loop (traffic -> predictor -> AV NMPC -> trust -> human -> '
                    'integrate) in one process and print final trust, mean explicability, '
                    'prediction RMSE, minimum gaps and fallback counts.')
    add_run_options(parser)
    parser.add_argument('--out', type=Path, default=None,
                        help='write the per-step table (CSV) here')
    parser.set_defaults(func=run)

