"""``trust-av run``: the ROS 2 node graph on one trace (in a namespace, on a private or a
given ROS domain), recorded to a rosbag2 bag; metrics and a plot."""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

from preceding_traffic.sources import load_trace
from preceding_traffic.traces import SpeedTrace, truncate
from trust_av.cli.options import (
    Progress,
    RunOptions,
    ceiling_at_end,
    collision_exit,
    format_metrics,
    positive_seconds,
    process_age_s,
    steps_value,
)
from trust_av.cli.typed_options import add_command, option
from trust_av.graph.domains import DOMAIN_ID_MAX, check_domain_id, check_namespace
from trust_av.system import run_record
from trust_av.system.closed_loop import SimResult, simulate
from trust_av.system.config import RunConfig, load_run_config
from trust_av.system.metrics import compute_metrics
from trust_av.system.outputs import replacing_outputs
from trust_monitor.model_interface import trust_ceiling

__all__: list[str] = []


@dataclasses.dataclass(frozen=True)
class GraphRunOptions(RunOptions):
    """``trust-av run``'s options."""

    bag: Path | None = option(
        '--bag', default=None,
        help='bag directory to write (default: bags/run_<trace>_<predictor>_alpha<alpha>)')
    overwrite: bool = option(
        '--overwrite',
        help='replace an existing bag directory, plot and logs, only if an '
             'earlier trust-av run wrote them (its .trust_av_output marker); '
             'they are replaced once the new ones are complete, and put back '
             'if the run fails or is stopped')
    no_plot: bool = option(
        '--no-plot',
        help='do not draw BAG.png (saves about 1 CPU-s per run in scripted '
             'batches; the metrics are printed either way)')
    max_steps: int = option('--max-steps', type=steps_value, default=0,
                            help='stop after this many steps (default: the whole trace)')
    namespace: str = option(
        '--namespace', default='/', metavar='NS',
        help='ROS namespace of every node (as --ros-args -r __ns:=NS): the '
             'topics become NS/ego/odom, NS/tf, ... and the bag records those '
             'names; a valid ROS 2 namespace (absolute, tokens of letters, '
             'digits and _ not starting with a digit). Two runs in different '
             'namespaces on one --domain-id do not hear each other '
             '(default: %(default)s)')
    domain_id: str | None = option(
        '--domain-id', default=None, metavar='N',
        help=f'run on ROS_DOMAIN_ID N (0..{DOMAIN_ID_MAX}, what Fast DDS can '
             'use), shared with other graphs in other namespaces: refused if '
             'a node in --namespace or a publisher on one of its topics is '
             'already there, and stopped if one appears. Default: lease a '
             'free, private domain that nothing else uses')
    startup_timeout_s: float = option(
        '--startup-timeout-s', type=positive_seconds, default=30.0,
        help='how long to wait for the graph to connect (default: %(default)s)')


def run(args: GraphRunOptions) -> int:
    """Run ``trust-av run``."""
    began = time.monotonic() - process_age_s()     # Python's start-up and imports included
    # imported here: rclpy, rosbags and matplotlib cost about 1 CPU-s, which --help and a
    # refused option do not need to pay
    from trust_av.graph.orchestrator import run_graph_records

    namespace = check_namespace(args.namespace, '--namespace')
    domain_id = None if args.domain_id is None else domain_id_value(args.domain_id)
    config = load_run_config(args.params_files, args.overrides())
    trace = truncate(load_trace(config.trace.trace, config.planner.dt_s, config.trace),
                     args.max_steps)
    bag: Path = args.bag or Path('bags') / (
        f'run_{trace.name}_{config.planner.predictor}_alpha{config.planner.alpha:g}')
    with replacing_outputs(bag, overwrite=args.overwrite, command='run') as outputs:
        print(run_record.header(config), flush=True)
        bar = Progress(f'graph {trace.name}', trace.steps, shown=not args.no_progress,
                       timed=False)
        graph_began = time.monotonic()
        try:
            result, records = run_graph_records(
                config, config.trace.trace, trace, outputs.bag,
                max_steps=args.max_steps, startup_timeout_s=args.startup_timeout_s,
                log_dir=outputs.logs, on_step=bar.update,
                namespace=namespace, domain_id=domain_id)
        finally:
            bar.close()
        graph_s = time.monotonic() - graph_began
        metrics = compute_metrics(records, config.min_safe_gap_m)
        title = (f'TAC-{config.planner.predictor.upper()} on {trace.name}, '
                 f'alpha = {config.planner.alpha:g} (ROS 2 graph, domain {result.domain_id}'
                 f'{"" if namespace == "/" else ", namespace " + namespace})')
        baseline = None
        if not args.no_plot:
            from trust_av.study.plots import run_overview  # matplotlib: ~1 CPU-s

            baseline = trust_unaware(args, config, trace)
            run_overview(records[:metrics.steps], title, outputs.plot,
                         performance_threshold=config.trust.performance_threshold,
                         ceiling=trust_ceiling(config.trust_model()),
                         baseline=None if baseline is None
                         else baseline.records[:metrics.steps])
    print(format_metrics(metrics, title, trust_ceiling=ceiling_at_end(config, trace)))
    if baseline is not None:
        print(f'trust-unaware AV (alpha = 0, in-process, same drive; drawn beside it): final '
              f'trust {baseline.metrics.final_trust:.3f}, mean E '
              f'{baseline.metrics.mean_explicability:.5f}')
    total_s = time.monotonic() - began
    finishing_s = graph_s - result.startup_s - result.steps_s
    print(f'time {total_s:.1f} s in all: start-up of the graph {result.startup_s:.1f} s, '
          f'{result.steps} steps {result.steps_s:.1f} s '
          f'({result.steps * trace.dt_s / max(result.steps_s, 1e-9):.0f}x real time), '
          f'finishing and reading back the recording {finishing_s:.1f} s, Python start-up, '
          'loading, metrics'
          f'{"" if args.no_plot else ", the alpha = 0 comparison and the plot"} '
          f'{total_s - graph_s:.1f} s')
    print(f'recording (rosbag2): {outputs.bag}')
    if not args.no_plot:
        print(f'plot: {outputs.plot}')
    print(f'node logs: {outputs.logs}')
    print(f'effective parameters of every node: {outputs.logs / run_record.PARAMS_FILE_NAME} '
          f"(and the bag's custom_data {run_record.PARAMS_KEY})")
    return collision_exit(metrics, 'run')


def trust_unaware(args: RunOptions, config: RunConfig,
                  trace: SpeedTrace) -> SimResult | None:
    """The same drive with alpha = 0 (the AV ignores explicability), in-process (the graph
    gives the same trajectory); None when ``config`` is already at alpha = 0."""
    if config.planner.alpha == 0.0:
        return None
    overrides = args.overrides()
    overrides['planner'] = {**overrides['planner'], 'alpha': 0.0}
    return simulate(load_run_config(args.params_files, overrides), trace)


def domain_id_value(text: str) -> int:
    """``--domain-id``: a whole number in 0..232.

    Raises:
        TrustAvAppError: it is not (one line naming the option).
    """
    try:
        value: object = int(text, 10)
    except ValueError:
        value = text
    return check_domain_id(value, '--domain-id')


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add ``run`` to ``trust-av``."""
    parser = subparsers.add_parser(
        'run', help='the ROS 2 node graph on one trace, recorded to a rosbag2 bag',
        description='Start the six nodes (preceding_traffic, planner, ego_plant, human_driver, '
                    'trust_monitor, recorder) as separate processes on a private ROS domain '
                    '(or on --domain-id, in --namespace), '
                    'step them in lock-step on sim time to the end of the trace, record every '
                    'topic to a rosbag2 bag directory (metadata.yaml + MCAP), then print the '
                    'metrics and write a plot (BAG.png) and the node logs (BAG.logs/) beside '
                    'it. However the run ends the bag is finished and readable. Exit codes: 0 '
                    'done, 3 a collision (a gap at or below 0 m: the run ends with that '
                    'step, the summary says so; the bag is complete up to it), 2 bad input, '
                    'a node failed (named) or the disk is full, 130 interrupted (SIGINT), '
                    '143 terminated (SIGTERM), 129 its terminal closed (SIGHUP; not under '
                    'nohup).')
    add_command(parser, GraphRunOptions, run)
