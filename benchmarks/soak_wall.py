"""Wall-clock soak: the whole node graph in wall mode at 10 Hz for half an hour of real time.

    python benchmarks/soak_wall.py [--duration-min 32] [--baseline-min 5] [--keep DIR]

``benchmarks/soak.py`` steps an hour of sim time through the lock-step graph in seconds;
this runs every node on its wall-clock timer (``trust-av shadow --whole-graph``, i.e.
:func:`trust_av.graph.shadow.run_wall_graph`; CA predictor unless ``--predictor
gru``) for ``--duration-min``
minutes of wall time after ``/sim/start``. This process records every topic to a rosbag2
bag directory, as in that mode.

The lead vehicle is ``bags/commute_am`` then ``bags/commute_pm`` (then am again, as often as
needed to outlast the run): their odometry samples, each trip's times shifted to start 1 s
after the previous trip's end, written with the project's own bag writer
(:func:`preceding_traffic.bags.write_trace_bag`) as one rosbag2 bag in a temporary
directory, which ``preceding_traffic`` replays at real-time speed.

Every minute (``--sample-s``; and once in the last second) it samples each node process's
and its own resident memory (``/proc/<pid>/status`` VmRSS), open file descriptors
(``/proc/<pid>/fd``) and threads (``/proc/<pid>/task``). At the end it reads the bag back
with rosbags and checks, every topic the run records (the table's topics but the step clock
and ``/sim/start``; the bag holds exactly these), against its publishing nodes' own count of
what they published (their loop statistics, ``jitter_report_path``, summed over the topic's
publishers, plus the table's ``initial`` messages each node publishes before its loop
starts) and the DDS publication sequence number of every recorded message (each publisher's
own count, from 1; the publishers of ``/tf`` are told apart by the transform's child frame):

- holes: no sequence number of a publisher is missing between its first and last recorded
  message;
- start edge: the messages before a publisher's first recorded one were published before
  the recorder had matched the publisher (the wall-mode profiles are volatile: a late
  subscriber gets nothing old). Allowed only before ``/sim/start``: a publisher's first
  recorded message is its first, or was received before ``/sim/start`` (the runner sends
  ``/sim/start`` only once this process has received every publisher that publishes before
  it);
- stop edge: at most :data:`soak_wall_checks.STOP_EDGE` message per publisher published and
  not recorded at the end (the one a node may publish while it is being stopped: the
  recorder subscribes to the odometry best effort, as it is published, and there is no
  acknowledgement to wait for; the other topics it takes reliably, as they are published,
  so a stopping node waits until they are acknowledged: 0 there);
- so published - recorded = start edge + stop edge, nothing else;
- no gap between consecutive messages (header stamps, from ``/sim/start`` on) longer than
  ``--max-gap-s`` (default 1 s = 10 periods: longer is a lost run of messages or a stalled
  node, not scheduling jitter; the planner calls an input stale after 0.5 s, which the table
  also counts).

It fails (exit 1, one line) if any check fails, or a process's RSS grows by more than
``--rss-limit-mb`` (20 MB) from ``--baseline-min`` (minute 5) to the end, or its open file
descriptors or threads are more at the end than at the baseline. It prints a table and
writes ``--out`` (default ``benchmarks/soak_wall_results.json``): cores, date, load
averages, per-process series per minute, the checks and each loop's statistics. No timing
threshold is applied: jitter is reported, not judged.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from soak_wall_checks import STOP_EDGE, Sequences, growth_checks, read_bag, topic_checks

from trust_av_common import registry
from trust_av_planner.predictors import PREDICTORS

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
TRIPS = (REPO / 'bags' / 'commute_am', REPO / 'bags' / 'commute_pm')
TRIP_GAP_S = 1.0
"""Time between the end of one trip and the start of the next in the chained bag, s."""
START_MARGIN_S = 60.0
"""The chained bag outlasts the run by at least this much (start-up happens before the
replay clock starts, so this is slack, not start-up time)."""
NOT_RECORDED = ('clock', 'sim/start')
"""Table rows a wall run does not record: the lock-step clock (not published in wall mode) and
the go signal (this process publishes it)."""
RECORDER = 'wall_recorder'
"""This process (it records the bag in wall mode)."""
NODES = ('preceding_traffic', 'planner', 'ego_plant', 'human_driver', 'trust_monitor')


def chain_trips(out: Path, min_span_s: float, config: Any) -> dict[str, Any]:
    """Write am, pm, am, ... (the commute bags' lead odometry, times shifted so each trip
    starts ``TRIP_GAP_S`` after the previous one ends) as one rosbag2 bag ``out`` spanning
    at least ``min_span_s``; returns what was chained."""
    from preceding_traffic.bags import read_bag_samples, write_trace_bag

    times: list[np.ndarray] = []
    speeds: list[np.ndarray] = []
    names: list[str] = []
    end = None
    while end is None or end - times[0][0] < min_span_s:
        trip = TRIPS[len(names) % len(TRIPS)]
        t, v = read_bag_samples(trip, config.bag_topic, config.bag_message_type, config)
        start = 0.0 if end is None else end + TRIP_GAP_S
        times.append(t - t[0] + start)
        speeds.append(v)
        names.append(trip.name)
        end = float(times[-1][-1])
    all_t, all_v = np.concatenate(times), np.concatenate(speeds)
    count = write_trace_bag(all_t, all_v, out, config.bag_topic)
    return {'trips': names, 'span_s': float(all_t[-1] - all_t[0]), 'messages': count,
            'format': 'rosbag2 MCAP bag of nav_msgs/msg/Odometry (write_trace_bag)'}


def process_sample(pid: int) -> dict[str, float]:
    """Resident memory (MB), open file descriptors and threads of process ``pid``."""
    proc = Path('/proc') / str(pid)
    status = (proc / 'status').read_text()
    rss_kb = next(int(line.split()[1]) for line in status.splitlines()
                  if line.startswith('VmRSS:'))
    return {'rss_mb': rss_kb / 1024, 'fds': len(os.listdir(proc / 'fd')),
            'threads': len(os.listdir(proc / 'task'))}


def recorded_topics() -> list[Any]:
    """The table's rows a wall run records (:data:`NOT_RECORDED` left out)."""
    from trust_av_common.topics import TOPICS

    return [t for t in TOPICS if t.name not in NOT_RECORDED]


class Sources:
    """Which publisher sent a recorded message: the only one of a single-publisher topic;
    on ``tf`` the node that owns the transform's child frame
    (:data:`trust_av_common.topics.VEHICLE_FRAMES`)."""

    def __init__(self, topics: dict[str, Any]) -> None:
        from trust_av_common.topics import VEHICLE_FRAMES

        self.topics = topics
        self.owner = {frame: node for node, frame in VEHICLE_FRAMES.items()}
        self._classes: dict[str, Any] = {}

    def __call__(self, topic: str, data: bytes) -> str:
        """The publishing node of ``data`` (serialized) on ``topic``."""
        row = self.topics[topic]
        if len(row.publishers) == 1:
            return str(row.publishers[0])
        if row.msgtype != 'tf2_msgs/msg/TFMessage':
            raise RuntimeError(f'{topic}: {len(row.publishers)} publishers of '
                               f'{row.msgtype}, which this soak cannot tell apart')
        from rclpy.serialization import deserialize_message

        from trust_av_common.ros.messages import message_class

        cls = self._classes.setdefault(row.msgtype, message_class(row.msgtype))
        frames = {t.child_frame_id for t in deserialize_message(data, cls).transforms}
        return ','.join(sorted(self.owner.get(f, f) for f in frames))


class Sampler:
    """The once-a-second callback of the run: a sample per process every ``sample_s``
    seconds (a minute by default) and one in the run's last second."""

    def __init__(self, duration_s: float, sample_s: float = 60.0) -> None:
        self.duration_s = duration_s
        self.sample_s = sample_s
        self.series: dict[str, list[dict[str, float]]] = {}
        self.start_ns: int | None = None
        self._next_s = 0.0
        self._final = False

    def __call__(self, pids: dict[str, int], elapsed_s: float) -> None:
        if self.start_ns is None:
            self.start_ns = time.time_ns() - round(elapsed_s * 1e9)
        last = elapsed_s >= self.duration_s - 1.5 and not self._final
        if elapsed_s < self._next_s and not last:
            return
        if elapsed_s >= self._next_s:
            self._next_s += self.sample_s
        self._final = self._final or last
        for name, pid in {**pids, RECORDER: os.getpid()}.items():
            self.series.setdefault(name, []).append(
                {'t_min': round(elapsed_s / 60.0, 3), **process_sample(pid)})


def run_soak(args: argparse.Namespace, work: Path) -> dict[str, Any]:
    """Chain the trips, run the graph, read the bag back; returns the figures."""
    from preceding_traffic.sources import load_trace
    from trust_av.graph.shadow import run_wall_graph
    from trust_av.system.config import load_run_config
    from trust_av_common.topics import qualified

    topics = {qualified(t.name): t for t in recorded_topics()}
    duration_s = args.duration_min * 60.0
    base = load_run_config()
    chain = work / 'commute_chain'
    chained = chain_trips(chain, duration_s + START_MARGIN_S, base.trace)
    config = load_run_config((), {'preceding_traffic': {'trace': str(chain)},
                                  'planner': {'predictor': args.predictor}})
    trace = load_trace(str(chain), config.planner.dt_s, config.trace)
    sampler = Sampler(duration_s, args.sample_s)
    sequences: dict[str, Sequences] = {}

    sources = Sources(topics)

    def on_message(topic: str, seq: int, data: bytes) -> None:
        sequences.setdefault(topic, Sequences()).add(seq, time.time_ns(),
                                                     sources(topic, data))

    load_before = os.getloadavg()
    started = time.monotonic()
    run = run_wall_graph(config, str(chain), trace, work / 'soak', duration_s=duration_s,
                         rate_hz=args.rate_hz, every_second=sampler, on_message=on_message,
                         lossless=False)  # its own checks below say what was lost
    wall_s = time.monotonic() - started
    load_after = os.getloadavg()
    if sampler.start_ns is None:
        raise RuntimeError('the run ended before its first second')
    recorded = read_bag(work / 'soak', sampler.start_ns)
    published = {name: t.initial + sum(run.loops[node].get('published', {}).get(name, 0)
                                       for node in t.publishers)
                  for name, t in topics.items()}
    rows, problems = topic_checks(published, recorded, sequences, start_ns=sampler.start_ns,
                                  max_gap_s=args.max_gap_s,
                                  publishers={n: len(t.publishers) for n, t in topics.items()})
    for row in rows:
        row['node'] = ','.join(topics[row['topic']].publishers) if row['topic'] in topics \
            else '?'

    growth, grow_problems = growth_checks(sampler.series, args.baseline_min, args.rss_limit_mb)
    return {
        'date': datetime.datetime.now(datetime.UTC).isoformat(timespec='seconds'),
        'cpu_count': os.cpu_count(), 'load_average_before': load_before,
        'load_average_after': load_after, 'duration_min': args.duration_min,
        'wall_s_including_startup': round(wall_s, 1), 'rate_hz': args.rate_hz,
        'predictor': args.predictor, 'lead': chained,
        'limits': {'baseline_min': args.baseline_min, 'rss_growth_mb': args.rss_limit_mb,
                   'fd_growth': 0, 'thread_growth': 0, 'max_gap_s': args.max_gap_s,
                   'stop_edge_messages': STOP_EDGE,
                   'start_edge': 'only messages published before /sim/start'},
        'topics': rows, 'growth': growth, 'series': sampler.series,
        'loops': {name: {k: loop[k] for k in ('ticks', 'jitter_ms', 'compute_ms', 'published')
                         if k in loop}
                  for name, loop in run.loops.items()},
        'problems': problems + grow_problems}


def print_table(figures: dict[str, Any]) -> None:
    """The checks and the growth, as two tables."""
    print(f'\nwall-clock soak: {figures["duration_min"]:g} min at {figures["rate_hz"]:g} Hz '
          f'({figures["lead"]["trips"]}), {figures["cpu_count"]} cores, load average '
          f'{figures["load_average_before"][0]:.1f} -> {figures["load_average_after"][0]:.1f}')
    width = max(18, *(len(r['node']) for r in figures['topics']))
    print(f'{"topic":34s} {"node":{width}s} {"published":>9s} {"recorded":>9s} {"start":>5s} '
          f'{"holes":>5s} {"stop":>4s} {"max gap s":>9s} {"> 0.5 s":>7s}')
    for r in figures['topics']:
        print(f'{r["topic"]:34s} {r["node"]:{width}s} {r["published"]:9d} {r["recorded"]:9d} '
              f'{r["start_edge"]:5d} {r["holes"]:5d} {r["stop_edge"]:4d} '
              f'{r["max_gap_s"]:9.3f} {r["gaps_over_stale_s"]:7d}')
    print(f'\n{"process":18s} {"RSS MB base -> end":>20s} {"growth":>7s} {"fds":>9s} '
          f'{"threads":>9s} {"ticks":>6s} {"jitter p99 ms":>13s}')
    for name, grow in figures['growth'].items():
        series = figures['series'][name]
        base = next(s for s in series if s['t_min'] == grow['from_min'])
        end = series[-1]
        loop = figures['loops'].get(name)
        ticks = f'{loop["ticks"]:6d}' if loop else f'{"-":>6s}'
        p99 = f'{loop["jitter_ms"]["p99"]:13.2f}' if loop else f'{"-":>13s}'
        print(f'{name:18s} {base["rss_mb"]:9.1f} -> {end["rss_mb"]:7.1f} {grow["rss_mb"]:+7.1f} '
              f'{base["fds"]:4.0f}->{end["fds"]:<4.0f} {base["threads"]:4.0f}->'
              f'{end["threads"]:<4.0f} {ticks} {p99}')


def main(argv: list[str] | None = None) -> int:
    """Run the soak; exit 0 if every check holds, 1 (one line) if not."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--duration-min', type=float, default=32.0,
                        help='wall time after /sim/start, minutes (default: %(default)s)')
    parser.add_argument('--baseline-min', type=float, default=5.0,
                        help='growth is measured from this minute to the end (default: '
                             '%(default)s)')
    parser.add_argument('--sample-s', type=float, default=60.0,
                        help='seconds between two samples of every process (default: '
                             '%(default)s; one more is taken in the last second)')
    parser.add_argument('--rss-limit-mb', type=float, default=20.0)
    parser.add_argument('--max-gap-s', type=float, default=1.0)
    parser.add_argument('--rate-hz', type=float, default=10.0)
    parser.add_argument('--predictor', default='ca',
                        choices=registry.names(PREDICTORS),
                        help='registered plan estimator (default: %(default)s, the shipped '
                             'default)')
    parser.add_argument('--out', type=Path, default=HERE / 'soak_wall_results.json')
    parser.add_argument('--keep', type=Path, default=None,
                        help='keep the recording, the chained bag and the node logs here')
    args = parser.parse_args(argv)
    if not (args.duration_min > args.baseline_min >= 0 and args.duration_min * 60 >= 2):
        print(f'error: --duration-min ({args.duration_min:g}) must exceed --baseline-min '
              f'({args.baseline_min:g}) >= 0', file=sys.stderr)
        return 2
    if not 1.0 <= args.sample_s <= args.duration_min * 60.0:
        print(f'error: --sample-s ({args.sample_s:g}) must be 1 s or more and at most the '
              'duration', file=sys.stderr)
        return 2
    if args.keep is not None:
        args.keep.mkdir(parents=True, exist_ok=True)
        figures = run_soak(args, args.keep)
    else:
        with tempfile.TemporaryDirectory() as tmp:
            figures = run_soak(args, Path(tmp))
    print_table(figures)
    args.out.write_text(json.dumps(figures, indent=1) + '\n')
    print(f'wrote {args.out}')
    if figures['problems']:
        print(f'error: soak failed: {"; ".join(figures["problems"])}', file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
