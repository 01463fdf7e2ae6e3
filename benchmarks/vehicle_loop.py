"""Vehicle in the loop: the planner and the trust monitor against a stand-in vehicle, at real
time, connected by remapping only.

    python benchmarks/vehicle_loop.py [--duration-s 60] [--rate-hz 10] [--out report.json]

On a leased ROS domain, three processes: ``trust_av_planner.vehicle_standin_node`` (its own
topic names ``/vehicle/odom``, ``/perception/lead_vehicle/odom``, ``/control/accel_cmd``; the
commute_am lead at real time, measurements published half a period late, 5 % dropped, the
lead silent for 1 s at 30 s), and ``planner`` and ``trust_monitor`` in wall mode exactly as
``ros2 run`` starts them, their topics remapped onto the vehicle's
(``-r /preceding_vehicle/odom:=/perception/lead_vehicle/odom -r /ego/odom:=/vehicle/odom
-r /ego/accel_cmd:=/control/accel_cmd``), ``lead_preview: constant_speed`` (a vehicle has no
recorded future), no follower (``human_odom_topic: ''``, CA predictor). Writes one JSON: the
stand-in's log (every tick's gap, applied command and its age, what was sent, the planner
status and trust it heard) and each node's loop statistics (jitter, compute time).
``tests/graph/test_vehicle_loop.py`` checks the behaviour; ``bench_shadow.py --vehicle`` reports
the jitter. Timing figures here are indicative only.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import yaml

from trust_av.graph.domains import lease_domain
from trust_av.graph.lifecycle_client import MANAGED_NODES, set_states
from trust_av.system.config import DEFAULT_PARAMS_FILE

REMAPS = {'/preceding_vehicle/odom': '/perception/lead_vehicle/odom',
          '/ego/odom': '/vehicle/odom', '/ego/accel_cmd': '/control/accel_cmd'}
"""The planner's standard names -> the stand-in vehicle's."""


@contextlib.contextmanager
def lifecycle_manager(domain: int) -> Iterator[tuple[Any, Any]]:
    """A node and its executor on a private rclpy context in ``domain``, for a process that
    starts nodes without being a ROS node itself."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.utilities import try_shutdown

    context = Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node('lifecycle_manager', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        yield node, executor
    finally:
        executor.shutdown()
        node.destroy_node()
        try_shutdown(context=context)


def node_command(module: str, name: str, params_files: list[Path],
                 remaps: dict[str, str]) -> list[str]:
    """``python -m <module> --ros-args ...``: what ``ros2 run`` starts."""
    command = [sys.executable, '-m', module, '--ros-args', '-r', f'__node:={name}']
    for path in params_files:
        command += ['--params-file', str(path)]
    for old, new in remaps.items():
        command += ['-r', f'{old}:={new}']
    return command


def stop(process: subprocess.Popen[bytes], grace_s: float = 5.0) -> None:
    """SIGINT, then SIGKILL after ``grace_s``."""
    if process.poll() is None:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(process.pid, signal.SIGINT)
        try:
            process.wait(grace_s)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()


def run_vehicle_loop(out_dir: Path, *, duration_s: float = 60.0, rate_hz: float = 10.0,
                     outage_start_s: float = 30.0, outage_s: float = 1.0,
                     drop_fraction: float = 0.05, seed: int = 1,
                     params_file: Path = DEFAULT_PARAMS_FILE,
                     startup_timeout_s: float = 60.0) -> dict[str, Any]:
    """Run the three processes; return the stand-in's report with the loop statistics.

    Raises:
        RuntimeError: a process failed or the stand-in did not finish in time (the message
            holds the last lines of every log).
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    report = out_dir / 'vehicle_standin.json'
    wall = {'clock_mode': 'wall', 'control_rate_hz': float(rate_hz)}
    run_params = out_dir / 'run_params.yaml'
    run_params.write_text(yaml.safe_dump({
        'planner': {'ros__parameters': {
            **wall, 'predictor': 'ca', 'human_odom_topic': '', 'lead_preview': 'constant_speed',
            'speed_max_from_trace': False, 'speed_max_mps': 36.0,
            'jitter_report_path': str(out_dir / 'planner.jitter.json')}},
        'trust_monitor': {'ros__parameters': {
            **wall, 'jitter_report_path': str(out_dir / 'trust_monitor.jitter.json')}},
        'vehicle_standin': {'ros__parameters': {
            **wall, 'duration_s': float(duration_s), 'outage_start_s': float(outage_start_s),
            'outage_s': float(outage_s), 'drop_fraction': float(drop_fraction), 'seed': seed,
            'report_path': str(report)}}}))
    specs = [('trust_av_planner.planner_node', 'planner', [params_file, run_params], REMAPS),
             ('trust_monitor.monitor_node', 'trust_monitor', [params_file, run_params], {}),
             ('trust_av_planner.vehicle_standin_node', 'vehicle_standin', [run_params], {})]
    processes: dict[str, subprocess.Popen[bytes]] = {}
    with lease_domain() as domain:
        env = dict(os.environ, ROS_DOMAIN_ID=str(domain),
                   ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST', PYTHONUNBUFFERED='1',
                   RMW_IMPLEMENTATION='rmw_fastrtps_cpp', ROS_LOG_DIR=str(out_dir / 'ros'))
        try:
            for module, name, files, remaps in specs:
                if name == 'vehicle_standin':
                    # the managed nodes in wall mode wait inactive: activated, as a vehicle's
                    # manager would, before the vehicle (its run's clock) starts
                    with lifecycle_manager(domain) as (node, executor):
                        set_states(node, executor, MANAGED_NODES, 'active',
                                   startup_timeout_s)
                with (out_dir / f'{name}.log').open('wb') as log:
                    processes[name] = subprocess.Popen(
                        node_command(module, name, files, remaps), stdout=log,
                        stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, env=env,
                        start_new_session=True)
            deadline = time.monotonic() + startup_timeout_s + duration_s + 30.0
            standin = processes['vehicle_standin']
            while standin.poll() is None and time.monotonic() < deadline:
                for name, process in processes.items():
                    if name != 'vehicle_standin' and process.poll() is not None:
                        raise RuntimeError(f'{name} exited with {process.returncode}'
                                           f'{_tails(out_dir)}')
                time.sleep(0.2)
            if standin.poll() is None or standin.returncode != 0 or not report.exists():
                raise RuntimeError(f'the stand-in vehicle did not finish its run{_tails(out_dir)}')
        finally:
            for process in processes.values():
                stop(process)
    data: dict[str, Any] = json.loads(report.read_text())
    data['loops'] = {name: json.loads((out_dir / f'{name}.jitter.json').read_text())
                     for name in ('planner', 'trust_monitor')}
    data['rate_hz'] = rate_hz
    return data


def _tails(out_dir: Path, lines: int = 8) -> str:
    text = ''
    for log in sorted(out_dir.glob('*.log')):
        tail = log.read_text(errors='replace').strip().splitlines()[-lines:]
        text += f'\n--- {log.name}\n' + '\n'.join(tail)
    return text


def main() -> int:
    """Run the loop and write the report."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--duration-s', type=float, default=60.0)
    parser.add_argument('--rate-hz', type=float, default=10.0)
    parser.add_argument('--out', type=Path, default=Path('vehicle_loop.json'))
    parser.add_argument('--work-dir', type=Path, default=None,
                        help='logs and node reports (default: beside --out)')
    args = parser.parse_args()
    work = args.work_dir or args.out.with_suffix('.logs')
    data = run_vehicle_loop(work, duration_s=args.duration_s, rate_hz=args.rate_hz)
    args.out.write_text(json.dumps(data) + '\n')
    for name, loop in data['loops'].items():
        j, c = loop['jitter_ms'], loop['compute_ms']
        print(f'{name:14s} {loop["ticks"]} ticks, jitter p50/p99/max {j["p50"]:.2f} / '
              f'{j["p99"]:.2f} / {j["max"]:.2f} ms, compute p99 {c["p99"]:.2f} ms')
    print(f'report: {args.out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
