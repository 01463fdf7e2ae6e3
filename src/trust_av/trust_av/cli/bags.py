"""``trust-av trace-to-bag``: a speed trace as a rosbag2 MCAP bag of ``nav_msgs/Odometry``."""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from preceding_traffic.traces import SHIPPED_TRACES, TraceConfig, read_samples, trace_path
from trust_av.cli.options import params_files_option
from trust_av.cli.typed_options import add_command, option, positional
from trust_av.system.config import load_run_config

__all__: list[str] = []


@dataclasses.dataclass(frozen=True)
class TraceToBagOptions:
    """``trust-av trace-to-bag``'s options."""

    trace: str = positional(help=f'one of {", ".join(SHIPPED_TRACES)} or a CSV path')
    out: Path = positional(help='bag directory to create (must not exist; missing parent '
                                'folders are created)')
    topic: str | None = option('--topic', default=None,
                               help="topic name (default: the params file's bag_topic)")
    params_files: tuple[Path, ...] = params_files_option()


def run(args: TraceToBagOptions) -> int:
    """Run ``trust-av trace-to-bag``."""
    from preceding_traffic.bags import write_trace_bag  # rosbags: only when a bag is written

    config = load_run_config(args.params_files)
    topic = args.topic or config.trace.bag_topic
    times, speeds = read_samples(trace_path(args.trace), TraceConfig(
        trace=args.trace, max_sample_gap_s=config.trace.max_sample_gap_s))
    count = write_trace_bag(times, speeds, args.out, topic)
    print(f'wrote {count} nav_msgs/msg/Odometry messages on {topic} to {args.out} '
          f'({times[0]:g} s to {times[-1]:g} s, stamps at the recorded times)')
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add ``trace-to-bag`` to ``trust-av``."""
    parser = subparsers.add_parser(
        'trace-to-bag', help='convert a speed trace to a rosbag2 MCAP bag',
        description='Write a time_s,speed_mps trace as a rosbag2 bag (MCAP storage) of '
                    'nav_msgs/msg/Odometry: speed in twist.twist.linear.x, position '
                    'integrated along x, header stamps and log times at the recorded times '
                    '(holes kept as they are). The bag replays with --trace BAG.')
    add_command(parser, TraceToBagOptions, run)
