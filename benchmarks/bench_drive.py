"""Driver-in-the-loop latency: input stamped in the page -> command applied in the graph ->
state back on the page.

    python benchmarks/bench_drive.py [--duration-s 60] [--out benchmarks/results_drive.json]
                                     [--study DIR]

Runs ``trust-av drive`` (one participant, one drive of each shipped condition, no practice)
with the synthetic participant of :mod:`trust_av_planner.drive.synthetic` in Debian's
headless chromium (Playwright), then reads every drive's ``/driver/latency`` from its bag and
prints and writes p50 / p99 / max of: the round trip (page clock), the graph part (pedal
sample received by the server -> the follower plant's acknowledgement received back) and
the rest (WebSocket both ways and the page's event loop), with the load average, the core
count and the date. Goal: round trip p99 <= 50 ms on localhost. Nothing here asserts it.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
GOAL_P99_MS = 50.0


def _stats(values_ms: np.ndarray) -> dict[str, float]:
    return {'p50': round(float(np.percentile(values_ms, 50)), 2),
            'p99': round(float(np.percentile(values_ms, 99)), 2),
            'max': round(float(values_ms.max()), 2), 'samples': len(values_ms)}


def latency_of(bag: Path) -> np.ndarray:
    """Rows (round trip, graph part, back part) in ms of one drive's bag."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        connections = [c for c in reader.connections if c.topic == '/driver/latency']
        rows = []
        for connection, _, raw in reader.messages(connections=connections):
            msg = reader.deserialize(raw, connection.msgtype)
            rows.append((msg.vector.x, msg.vector.y, msg.vector.z))
    return np.array(rows).reshape(-1, 3) * 1e3


def main() -> int:
    """Run the drive latency benchmark."""
    from playwright.sync_api import sync_playwright

    from trust_av_planner.drive.synthetic import (
        CHROMIUM,
        CHROMIUM_ARGS,
        Participant,
        drive_once,
    )

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--duration-s', type=float, default=60.0,
                        help='wall time of each drive, s (default: %(default)s)')
    parser.add_argument('--out', type=Path, default=HERE / 'results_drive.json')
    parser.add_argument('--study', type=Path, default=None,
                        help='keep the study (bags, summary) in this new directory')
    args = parser.parse_args()
    if args.study is not None and args.study.exists():
        print(f'bench_drive: --study {args.study} exists', file=sys.stderr)
        return 2
    shipped = (REPO / 'config' / 'drive.yaml').read_text()
    with tempfile.TemporaryDirectory() as tmp:
        settings = Path(tmp) / 'drive.yaml'
        settings.write_text(re.sub(r'drive_duration_s: [0-9.]+',
                                   f'drive_duration_s: {args.duration_s}', shipped)
                            .replace('port: 8765', 'port: 0'))
        study = args.study if args.study is not None else Path(tmp) / 'study'
        process = subprocess.Popen(
            [sys.executable, '-m', 'trust_av_planner.cli', 'drive', '--study', str(study),
             '--participant', 'BENCH', '--drive-file', str(settings), '--no-practice'],
            stdout=subprocess.PIPE, text=True, env={**os.environ, 'PYTHONUNBUFFERED': '1'})
        assert process.stdout is not None
        url = re.search(r'open (http://\S+)', process.stdout.readline())
        if url is None:
            process.terminate()
            print('bench_drive: trust-av drive printed no URL', file=sys.stderr)
            return 2
        load_before = os.getloadavg()
        with sync_playwright() as playwright:
            browser = playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
            page = browser.new_page()
            page.goto(url.group(1))
            who = Participant()
            while page.evaluate('window.drive.phase') != 'finished':
                drive_once(page, who, until_s=args.duration_s + 120)
                page.wait_for_function("['ready', 'finished'].includes(window.drive.phase)",
                                       timeout=120_000)
            browser.close()
        output = process.communicate(timeout=120)[0]
        if process.returncode != 0:
            print(output, file=sys.stderr)
            return 2
        session = json.loads((study / 'BENCH' / 'session.json').read_text())
        drives = {}
        for record in session['drives']:
            rows = latency_of(study / record['bag'])
            drives[record['condition']] = {'round_trip_ms': _stats(rows[:, 0]),
                                           'graph_ms': _stats(rows[:, 1]),
                                           'rest_ms': _stats(rows[:, 0] - rows[:, 1])}
    results = {'date': datetime.datetime.now(datetime.UTC).isoformat(timespec='seconds'),
               'cpu_count': os.cpu_count(), 'load_average_1min': [load_before[0],
                                                                   os.getloadavg()[0]],
               'duration_s': args.duration_s, 'goal_round_trip_p99_ms': GOAL_P99_MS,
               'drives': drives}
    for name, figures in drives.items():
        for part, stats in figures.items():
            print(f'{name:>12} {part:>14}: p50 {stats["p50"]:7.2f}  p99 {stats["p99"]:7.2f}  '
                  f'max {stats["max"]:7.2f}  ({stats["samples"]} samples)')
    print(f'load average {results["load_average_1min"]}, {results["cpu_count"]} cores; '
          f'goal: round trip p99 <= {GOAL_P99_MS:g} ms')
    args.out.write_text(json.dumps(results, indent=1) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
