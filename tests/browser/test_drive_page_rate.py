"""The page keeps within the server's pedal rate limit by itself, in headless chromium
against the drive's web server alone (no graph): key presses and releases faster than the
control rate are all sent (none lost, the last one the release), and the server's gate,
fed the samples as they arrived, refuses none of them (it counts them on the page's clock,
their ``t_ms``, so a stall of this host that bunches them on the way changes nothing)."""

from __future__ import annotations

import queue
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from support.paths import REPO

from trust_av.drive.gate import DRIVING, INPUT_BURST, READY, Gate
from trust_av.drive.server import DriveServer

sys.path.insert(0, str(REPO / 'benchmarks'))
from synthetic_participant import CHROMIUM, CHROMIUM_ARGS

pytestmark = [pytest.mark.wall_clock,
              pytest.mark.skipif(not Path(CHROMIUM).exists(),
                                 reason='Debian chromium not installed (scripts/bootstrap.sh)')]

RATE_HZ = 10.0
HELLO = {'type': 'hello', 'control_rate_hz': RATE_HZ, 'input_burst': INPUT_BURST,
         'accel_max_mps2': 2.5, 'accel_min_mps2': -6.0}


@pytest.fixture
def served() -> Iterator[tuple[DriveServer, queue.Queue[tuple[dict[str, Any], int]]]]:
    inbox: queue.Queue[tuple[dict[str, Any], int]] = queue.Queue()
    server = DriveServer(lambda m, ns: inbox.put((m, ns)), lambda: HELLO, port=0)
    server.start()
    try:
        yield server, inbox
    finally:
        server.stop()


PRESSES = """async () => {
    const pause = () => new Promise((resolve) => setTimeout(resolve, 10));
    for (let k = 0; k < 20; k++) {
        window.dispatchEvent(new KeyboardEvent('keydown', {code: 'ArrowUp'}));
        await pause();
        window.dispatchEvent(new KeyboardEvent('keyup', {code: 'ArrowUp'}));
        await pause();
    }
    return drive.seq; }"""
"""40 presses and releases, 10 ms apart on the page's own timers (the page's bucket takes
3 at once and 9 a second: so many are over its rate unless the timers run 100 ms late
on average)."""


def test_fast_presses_stay_within_the_servers_rate_limit_and_none_is_lost(
        served: tuple[DriveServer, queue.Queue[tuple[dict[str, Any], int]]]) -> None:
    from playwright.sync_api import sync_playwright
    server, inbox = served
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            page = browser.new_page()
            page.goto(server.url)
            page.wait_for_function('window.drive.ws && window.drive.ws.readyState === 1')
            server.send({'type': 'phase', 'phase': 'driving', 'duration_s': 60.0})
            page.wait_for_function("window.drive.phase === 'driving'")
            pressed = page.evaluate(PRESSES)
            # released: the held-back release went out as soon as the bucket allowed
            page.wait_for_function(f'window.drive.seq > {pressed} && !window.drive.pressWaiting'
                                   ' && window.drive.lastSentPedal === 0')
            last = page.evaluate('window.drive.seq')
            held_back = page.evaluate('window.drive.heldBack')
        finally:
            browser.close()
    samples: list[tuple[dict[str, Any], int]] = []
    while not samples or samples[-1][0]['seq'] < last:
        message, arrived_ns = inbox.get(timeout=30)
        if message['type'] == 'input':
            samples.append((message, arrived_ns))
    assert [m['seq'] for m, _ in samples] == list(range(1, last + 1))   # none lost
    # the server's gate, fed the samples as they arrived (stamped with their send times),
    # refuses none, however this host's load bunched them on the way
    gate = Gate(RATE_HZ, -6.0, 2.5)
    gate.set_phase(READY)
    gate.set_phase(DRIVING)
    for message, arrived_ns in samples:
        gate.sample(message, arrived_ns)
    assert gate.refused_counts() == {}
    # more presses than the rate allows: the page held some back and sent them when it
    # could; the newest value (the release) was sent
    assert held_back > 0
    assert samples[-1][0]['accel_mps2'] == 0.0
    assert any(m['accel_mps2'] > 0.0 for m, _ in samples)
