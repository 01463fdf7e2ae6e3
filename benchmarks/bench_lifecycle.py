"""The planner node's first active ticks in wall mode, with and without the solver warm-up
that its lifecycle ``configure`` does.

Each case runs in a fresh process (nothing cached from the other): a ``planner`` node
(:class:`trust_av_planner.planner_node.PlannerNode`, ``clock_mode: wall``, no follower topic,
``autostart: false``) is configured and activated with its own transitions, then fed one set
of fresh inputs (lead odometry and preview, ego odometry in ``base_link``, the
``base_frame_id``: a vehicle's body frame) and stepped by calling its wall
tick directly; each tick's wall time (plan + publish) is measured. ``cold`` turns the warm-up
off (``planner_node.WARM_UP``: the node as before it was a managed node, whose first
tick made the output templates and the first solves). Prints the first ticks and the
configure time of each case and writes benchmarks/results_lifecycle.json (or --out). Not a
test: timings are noisy.

    python benchmarks/bench_lifecycle.py [--ticks 10] [--predictor ca] [--repeats 3]
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

CASE = r"""
import json, sys, time
import rclpy
from rclpy.lifecycle import TransitionCallbackReturn
import trust_av_planner.planner_node as planner_node
from trust_av_common.ros.messages import odometry, trajectory
SUCCESS = TransitionCallbackReturn.SUCCESS
warm, ticks, predictor = sys.argv[1] == 'warm', int(sys.argv[2]), sys.argv[3]
if not warm:
    planner_node.WARM_UP = False
args = ['bench', '--ros-args', '-p', 'clock_mode:=wall', '-p', "human_odom_topic:=''",
        '-p', 'autostart:=false', '-p', f'predictor:={predictor}']
rclpy.init(args=args)
node = planner_node.PlannerNode()
node.start(args)
start = time.perf_counter()
assert node.trigger_configure() == SUCCESS
configure_ms = 1e3 * (time.perf_counter() - start)
assert node.trigger_activate() == SUCCESS
step_s, steps = node.planner.grid
times = []
for k in range(ticks):
    now, t = time.time_ns(), 0.1 * k
    node.on_latest('traffic', odometry(now, 40.0 + 15.0 * t, 15.0, 'preceding_vehicle'))
    node.on_latest('preview', trajectory(now, step_s, frame_id='preceding_vehicle',
                                         velocities=[15.0] * steps))
    node.on_latest('ego', odometry(now, 15.0 * t, 15.0, 'base_link'))
    begin = time.perf_counter()
    node.wall_step()
    times.append(1e3 * (time.perf_counter() - begin))
assert node.stale_reason == '', node.stale_reason
node.destroy_node()
rclpy.shutdown()
print(json.dumps({'configure_ms': configure_ms, 'ticks_ms': times}))
"""


def run_case(warm: bool, ticks: int, predictor: str) -> dict[str, object]:
    """One fresh process: configure time and the first ``ticks`` active ticks, ms."""
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST', ROS_DOMAIN_ID='199')
    proc = subprocess.run([sys.executable, '-c', CASE, 'warm' if warm else 'cold', str(ticks),
                           predictor], capture_output=True, text=True, timeout=300, env=env,
                          check=False)
    if proc.returncode != 0:
        raise RuntimeError(proc.stderr[-2000:])
    result: dict[str, object] = json.loads(proc.stdout.strip().splitlines()[-1])
    return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--ticks', type=int, default=10)
    parser.add_argument('--predictor', default='ca')
    parser.add_argument('--repeats', type=int, default=3)
    parser.add_argument('--out', type=Path,
                        default=Path(__file__).parent / 'results_lifecycle.json')
    args = parser.parse_args(argv)
    if args.ticks < 2 or args.repeats < 1:
        print('error: --ticks must be >= 2 and --repeats >= 1', file=sys.stderr)
        return 2
    figures: dict[str, object] = {
        'date': datetime.datetime.now(datetime.UTC).isoformat(timespec='seconds'),
        'cpu_count': os.cpu_count(), 'load_average': os.getloadavg(),
        'predictor': args.predictor, 'period_ms': 100.0}
    for case in ('cold', 'warm'):
        runs = [run_case(case == 'warm', args.ticks, args.predictor)
                for _ in range(args.repeats)]
        first = [float(r['ticks_ms'][0]) for r in runs]  # type: ignore[index]
        later = [float(t) for r in runs for t in r['ticks_ms'][1:]]  # type: ignore[index]
        configure = [float(r['configure_ms']) for r in runs]  # type: ignore[arg-type]
        figures[case] = {'runs': runs, 'first_tick_ms': first,
                         'first_tick_median_ms': statistics.median(first),
                         'later_ticks_median_ms': statistics.median(later),
                         'configure_median_ms': statistics.median(configure)}
        print(f'{case}: first active tick {", ".join(f"{t:.1f}" for t in first)} ms '
              f'(median {statistics.median(first):.1f}), later ticks median '
              f'{statistics.median(later):.2f} ms, configure median '
              f'{statistics.median(configure):.0f} ms')
        time.sleep(0.5)
    print(f"load average {figures['load_average']}")
    args.out.write_text(json.dumps(figures, indent=2) + '\n')
    print(f'wrote {args.out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
