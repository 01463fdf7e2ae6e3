"""``trust-av shadow``: replay a real bag at real-time speed into the planner and the trust
monitor in wall-clock mode (or, with ``--whole-graph``, into every node in wall mode); record
their outputs; report loop jitter per node."""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path
from typing import TYPE_CHECKING

from preceding_traffic.sources import load_trace
from trust_av.cli.options import (
    BAG_TYPES,
    alpha_option,
    output_file,
    params_files_option,
    positive_hz,
    positive_seconds,
)
from trust_av.cli.typed_options import add_command, option
from trust_av.errors import TrustAvAppError
from trust_av.system import run_record
from trust_av.system.config import load_run_config
from trust_av.system.outputs import replacing_outputs
from trust_av_common import output_files, registry
from trust_av_common.wall_clock import format_summary
from trust_av_planner.planner import needs_follower_state
from trust_av_planner.planner_params import PlannerTopics, check_control_rate
from trust_av_planner.predictors import PREDICTORS

if TYPE_CHECKING:
    from trust_av.graph.shadow import ShadowRun

__all__: list[str] = []


def summary_lines(result: ShadowRun) -> list[str]:
    """The run's summary: messages per topic and one jitter line per loop."""
    lines = [f'wall-clock run: {result.duration_s:g} s of wall time, recording {result.bag}']
    lines += [f'  {topic}: {count} messages' for topic, count in result.counts.items()]
    lines += [f'  {name}: {format_summary(stats)}' for name, stats in result.loops.items()]
    return lines


@dataclasses.dataclass(frozen=True)
class ShadowOptions:
    """``trust-av shadow``'s options."""

    bag: Path = option('--bag', required=True,
                       help='rosbag2 bag (MCAP or sqlite3) whose lead vehicle is replayed')
    bag_topic: str | None = option(
        '--bag-topic', default=None,
        help="the lead vehicle's topic (default: preceding_traffic.bag_topic)")
    bag_type: str | None = option(
        '--bag-type', default=None, choices=BAG_TYPES,
        help='its message type (default: preceding_traffic.bag_message_type)')
    out: Path = option('--out', required=True,
                       help='bag directory to write (rosbag2: metadata.yaml + MCAP)')
    overwrite: bool = option(
        '--overwrite',
        help='replace an existing --out bag directory and its logs, only if '
             'an earlier trust-av command wrote them (its .trust_av_output '
             'marker); put back if this run fails or is stopped')
    duration_s: float | None = option(
        '--duration-s', type=positive_seconds, default=None,
        help='wall time to replay, s (default: the whole bag)')
    rate_hz: float | None = option(
        '--rate-hz', type=positive_hz, default=None,
        help="control rate, Hz (default: the params file's control_rate_hz)")
    alpha: float | None = alpha_option()
    predictor: str | None = option(
        '--predictor', choices=lambda: registry.names(PREDICTORS), default=None,
        help="registered plan estimator (default: the params file's)")
    whole_graph: bool = option(
        '--whole-graph',
        help='run all five nodes in wall mode (simulated ego and human '
             'follower) instead of the planner and monitor alone')
    json: Path | None = option(
        '--json', default=None,
        help='also write the loop statistics and message counts as JSON')
    startup_timeout_s: float = option(
        '--startup-timeout-s', type=positive_seconds, default=30.0,
        help='how long to wait for the nodes to connect (default: %(default)s)')
    params_files: tuple[Path, ...] = params_files_option()


def run(args: ShadowOptions) -> int:
    """Run ``trust-av shadow``."""
    # imported here, as in `trust-av run`: --help and a refused option do not pay for rclpy
    from trust_av.graph.shadow import run_shadow, run_wall_graph

    if args.json is not None:
        output_file(args.json, '--json')
    overrides: dict[str, dict[str, object]] = {'preceding_traffic': {'trace': str(args.bag)}}
    if args.bag_topic is not None:
        overrides['preceding_traffic']['bag_topic'] = args.bag_topic
    if args.bag_type is not None:
        overrides['preceding_traffic']['bag_message_type'] = args.bag_type
    planner: dict[str, object] = {}
    if args.alpha is not None:
        planner['alpha'] = args.alpha
    if args.predictor is not None:
        planner['predictor'] = args.predictor
    overrides['planner'] = planner
    config = load_run_config(args.params_files, overrides)
    topics = config.planner_topics
    rate_hz = args.rate_hz if args.rate_hz is not None else config.clock.control_rate_hz
    check_control_rate(config.planner, rate_hz)  # the planner node's rule, before any output
    if args.whole_graph and topics != PlannerTopics():
        files = ', '.join(str(p) for p in config.params_files)
        raise TrustAvAppError('--whole-graph runs the simulated nodes on the standard topics; '
                              f'the params files ({files}) remap the planner inputs: '
                              f'{topics}')
    if not args.whole_graph and needs_follower_state(config.planner):
        raise TrustAvAppError('trust-av shadow has no human follower state: predictor '
                              f'{config.planner.predictor} needs it (follower_state); '
                              'use one that does not or --whole-graph')
    trace = load_trace(str(args.bag), config.planner.dt_s, config.trace)
    whole_s = trace.steps * trace.dt_s
    duration_s = whole_s if args.duration_s is None else min(args.duration_s, whole_s)
    nodes = 'every node' if args.whole_graph else 'planner and trust_monitor'
    with replacing_outputs(args.out, overwrite=args.overwrite, command='shadow',
                           option='--out') as outputs:
        print(f'shadow: {args.bag} ({whole_s:g} s), replaying {duration_s:g} s at real time, '
              f'{nodes} at {rate_hz:g} Hz', flush=True)
        print(run_record.header(config), flush=True)
        if args.whole_graph:
            result = run_wall_graph(config, str(args.bag), trace, outputs.bag,
                                    duration_s=duration_s, rate_hz=rate_hz,
                                    startup_timeout_s=args.startup_timeout_s)
        else:
            result = run_shadow(config, trace, outputs.bag, duration_s=duration_s,
                                rate_hz=rate_hz, topics=topics,
                                startup_timeout_s=args.startup_timeout_s)
    print('\n'.join(summary_lines(result)))
    if args.json is not None:
        output_files.write_text(args.json, json.dumps(
            {'bag': str(args.bag), 'duration_s': duration_s, 'rate_hz': rate_hz,
             'counts': result.counts, 'loops': result.loops}, indent=1) + '\n')
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add ``shadow`` to ``trust-av``."""
    parser = subparsers.add_parser(
        'shadow', help='replay a bag at real time into the planner and monitor in wall mode',
        description='Start the planner and trust_monitor in wall-clock mode (clock_mode: wall) '
                    'on a private ROS domain, replay the lead vehicle of a rosbag2 bag at '
                    "real-time speed (stamps = now; the ego is simulated from the planner's "
                    'commands, there is no human follower), record the inputs and outputs to '
                    'MCAP (log time = wall time) and print loop jitter p50/p99/max per node. '
                    'With --whole-graph every node runs in wall mode instead: the traffic node '
                    'replays the bag, ego_plant and human_driver simulate the two vehicles '
                    '(so a predictor that needs the follower state works), and every topic '
                    'is recorded. '
                    'Exit codes: 0 done, 2 bad input or a node failed (named), 130 interrupted.')
    add_command(parser, ShadowOptions, run)
