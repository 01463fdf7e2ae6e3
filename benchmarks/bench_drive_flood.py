"""What a flood of 10,000 messages from one WebSocket client does to another client's state
frames, at the drive's web server alone (no graph, no browser: what the server itself adds).

    python benchmarks/bench_drive_flood.py [--floods 3] [--out benchmarks/results_drive_flood.json]

The server (``trust_av.drive.server.DriveServer``) runs with the drive's message gate
(``trust_av.drive.gate.Gate``, in the driving phase) behind it; a thread of this
process sends a state frame every 50 ms (as the drive's loop does on each odometry), one
client (with the page's origin and token, as a second tab) receives them and stamps their
arrival, and another client, the driving one, sends 10,000 messages as fast as it can
(pedal samples at 1e308 and forged acknowledgements, alternating) until the server drops it.
Per flood: the frames' latency (sent by the thread -> received by the other client) and the
largest gap between two of its frames, in the 3 s before the flood and from its start to
1 s after it. ``benchmarks/bench_drive.py --flood`` measures the same through the browser
and the graph. Nothing here asserts a figure.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
FRAME_PERIOD_S = 0.05
MESSAGES = 10_000


def one_flood() -> dict[str, Any]:
    """One server, one flood; its figures."""
    from websockets.exceptions import ConnectionClosed
    from websockets.sync.client import connect

    from trust_av.drive.gate import DRIVING, READY, Gate
    from trust_av.drive.server import DriveServer

    gate = Gate(10.0, -6.0, 2.5)
    gate.set_phase(READY)
    gate.set_phase(DRIVING)

    def on_message(message: dict[str, Any], now_ns: int) -> None:
        if gate.admit(message) and message['type'] == 'input':
            gate.sample(message, now_ns)
        elif message['type'] == 'ack':
            gate.echo(message, now_ns)

    server = DriveServer(on_message, lambda: {'type': 'hello'}, on_refused=gate.refuse,
                         port=0)
    server.start()
    headers = {'Origin': f'http://127.0.0.1:{server.port}'}
    url = f'ws://127.0.0.1:{server.port}/ws?token={server.token}'
    done = threading.Event()
    frames: list[tuple[int, int]] = []          # (received ns, sent ns)

    def produce() -> None:
        while not done.is_set():
            server.send({'type': 'state', 'sent_ns': time.time_ns(),
                         'vehicles': {'lead': [60.0, 10.0], 'av': [30.0, 10.0],
                                      'you': [0.0, 10.0]}})
            time.sleep(FRAME_PERIOD_S)

    def observe(ws: Any) -> None:
        try:
            while True:
                message = json.loads(ws.recv(timeout=5))
                if message['type'] == 'state':
                    frames.append((time.time_ns(), int(message['sent_ns'])))
        except (ConnectionClosed, TimeoutError):
            return

    sent = 0
    try:
        with connect(url, additional_headers=headers) as flooder, \
                connect(url, additional_headers=headers) as other:
            threads = [threading.Thread(target=produce, daemon=True),
                       threading.Thread(target=observe, args=(other,), daemon=True)]
            for thread in threads:
                thread.start()
            time.sleep(3.0)
            start = time.time_ns()
            try:
                for k in range(MESSAGES):
                    flooder.send(json.dumps(
                        {'type': 'input', 'seq': k, 'accel_mps2': 1e308} if k % 2
                        else {'type': 'ack', 'seq': k}))
                    sent = k + 1
            except ConnectionClosed:
                pass                               # dropped by the server: the expected end
            end = time.time_ns()
            time.sleep(1.5)
            done.set()
            other.close()
            for thread in threads:
                thread.join(timeout=10)
    finally:
        server.stop()
    got = np.array(frames, dtype=np.int64)
    latency_ms = (got[:, 0] - got[:, 1]) / 1e6
    gaps_ms = np.diff(got[:, 0]) / 1e6
    before = got[:, 0] < start
    during = (got[:, 0] >= start) & (got[:, 0] < end + 1_000_000_000)
    return {'sent_before_dropped': sent, 'flood_send_ms': round((end - start) / 1e6, 1),
            'refused': gate.refused_counts(),
            'latency_before_p50_ms': round(float(np.median(latency_ms[before])), 2),
            'latency_before_max_ms': round(float(latency_ms[before].max()), 2),
            'latency_flood_p50_ms': round(float(np.median(latency_ms[during])), 2),
            'latency_flood_max_ms': round(float(latency_ms[during].max()), 2),
            'gap_before_max_ms': round(float(gaps_ms[before[1:]].max()), 1),
            'gap_flood_max_ms': round(float(gaps_ms[during[1:]].max()), 1)}


def main() -> int:
    """Run the server flood benchmark."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--floods', type=int, default=3, help='floods, one server each')
    parser.add_argument('--out', type=Path, default=HERE / 'results_drive_flood.json')
    args = parser.parse_args()
    if args.floods < 1:
        print('bench_drive_flood: --floods must be >= 1', file=sys.stderr)
        return 2
    load = os.getloadavg()[0]
    runs = [one_flood() for _ in range(args.floods)]
    print(f'{"flood":>5} {"sent":>6} {"send ms":>8} {"latency p50/max before":>23} '
          f'{"during":>14} {"largest gap before":>19} {"during":>7}')
    for k, run in enumerate(runs):
        print(f'{k + 1:>5} {run["sent_before_dropped"]:>6} {run["flood_send_ms"]:>8} '
              f'{run["latency_before_p50_ms"]:>14} / {run["latency_before_max_ms"]:<6} '
              f'{run["latency_flood_p50_ms"]:>6} / {run["latency_flood_max_ms"]:<6} '
              f'{run["gap_before_max_ms"]:>19} {run["gap_flood_max_ms"]:>7}')
    print(f'frames every {FRAME_PERIOD_S * 1e3:g} ms; load average {load:.1f} on '
          f'{os.cpu_count()} cores; ms')
    args.out.write_text(json.dumps({
        'date': datetime.datetime.now(datetime.UTC).isoformat(timespec='seconds'),
        'cpu_count': os.cpu_count(), 'load_average_1min': round(load, 2),
        'frame_period_s': FRAME_PERIOD_S, 'runs': runs}, indent=1) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
