"""The drive page in headless chromium, against the drive's web server alone (no graph): its
inputs (keyboard ramps, the pointer pedal, a gamepad, stamped samples at the control rate),
the non-blocking rating and reconnection, and its view (drawn by the vendored Konva, the AV's
brake lights lit while it is commanded to brake, nothing loaded from another origin). The
state stream is played by the test."""

from __future__ import annotations

import queue
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from support.paths import REPO

from trust_av.drive.server import DriveServer

sys.path.insert(0, str(REPO / 'benchmarks'))
from synthetic_participant import CHROMIUM, CHROMIUM_ARGS

pytestmark = [pytest.mark.wall_clock,
              pytest.mark.skipif(not Path(CHROMIUM).exists(),
                                 reason='Debian chromium not installed (scripts/bootstrap.sh)')]

HELLO = {'type': 'hello', 'rating_period_s': 1.0, 'control_rate_hz': 20.0,
         'accel_max_mps2': 2.5, 'accel_min_mps2': -6.0}
FAKE_PAD = """
navigator.getGamepads = () => [window.fakePad || null];
"""


@pytest.fixture
def served() -> Iterator[tuple[DriveServer, queue.Queue[dict[str, Any]]]]:
    inbox: queue.Queue[dict[str, Any]] = queue.Queue()
    server = DriveServer(lambda m, _ns: inbox.put(m), lambda: HELLO, port=0)
    server.start()
    try:
        yield server, inbox
    finally:
        server.stop()


@pytest.fixture
def page(served: tuple[DriveServer, Any]) -> Iterator[Any]:
    from playwright.sync_api import sync_playwright
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            tab = browser.new_page()
            tab.add_init_script(FAKE_PAD)
            tab.goto(served[0].url)
            tab.wait_for_function('window.drive.ws && window.drive.ws.readyState === 1')
            yield tab
        finally:
            browser.close()


def _inputs(inbox: queue.Queue[dict[str, Any]], wait_s: float) -> list[dict[str, Any]]:
    out, end = [], time.monotonic() + wait_s
    while time.monotonic() < end:
        try:
            message = inbox.get(timeout=0.05)
        except queue.Empty:
            continue
        if message['type'] == 'input':
            out.append(message)
    return out


def _drive(server: DriveServer, page: Any) -> None:
    server.send({'type': 'phase', 'phase': 'driving', 'duration_s': 60.0})
    page.wait_for_function("window.drive.phase === 'driving'")
    for k in range(5):      # a state stream, so the page has something to draw
        server.send({'type': 'state', 't_s': k * 0.1, 'trust': 0.5, 'vehicles': {
            'lead': [60.0 + k, 10.0], 'av': [30.0 + k, 10.0], 'you': [float(k), 10.0]}})
    page.wait_for_function("document.getElementById('gap').dataset.m !== undefined")


def test_keyboard_pointer_and_gamepad_drive_the_pedal(
        served: tuple[DriveServer, queue.Queue[dict[str, Any]]], page: Any) -> None:
    server, inbox = served
    _drive(server, page)
    assert page.locator('#gap').get_attribute('data-m') is not None
    _inputs(inbox, 0.3)                                   # what was sent before
    page.keyboard.down('ArrowUp')
    gas = _inputs(inbox, 1.0)
    page.keyboard.up('ArrowUp')
    assert gas[-1]['accel_mps2'] > gas[0]['accel_mps2'] and gas[-1]['accel_mps2'] > 1.0
    _inputs(inbox, 0.6)                                   # released: back to zero
    page.keyboard.down('KeyS')
    brake = _inputs(inbox, 0.6)
    page.keyboard.up('KeyS')
    assert brake[-1]['accel_mps2'] < -3.0
    # each sample is numbered; the press itself is sent at once (its first sample is gas
    # already), then about control_rate_hz of them a second; the page sends no time
    seqs = [m['seq'] for m in gas + brake]
    assert seqs == sorted(seqs) and not any('page_ms' in m for m in gas)
    assert 10 <= len(gas) <= 30
    # the press itself is sent at once, in the key's own event handler (not at the next
    # tick of the control rate): the page's sample number moves inside the keydown handler,
    # and that sample is gas (whatever the machine's load does to the timing of the above)
    _inputs(inbox, 0.3)
    before, after = page.evaluate("""() => {
        const before = drive.seq;
        window.dispatchEvent(new KeyboardEvent('keydown', {code: 'KeyW'}));
        const after = drive.seq;
        window.dispatchEvent(new KeyboardEvent('keyup', {code: 'KeyW'}));
        return [before, after]; }""")
    assert after == before + 1
    pressed = {m['seq']: m['accel_mps2'] for m in _inputs(inbox, 0.3)}
    assert pressed[after] > 0.0
    # the pointer pedal: held at the top is full gas, at the bottom full brake
    box = page.locator('#pedal').bounding_box()
    page.mouse.move(box['x'] + box['width'] / 2, box['y'] + 1)
    page.mouse.down()
    assert _inputs(inbox, 0.4)[-1]['accel_mps2'] == pytest.approx(2.5, abs=0.1)
    page.mouse.move(box['x'] + box['width'] / 2, box['y'] + box['height'] - 1)
    assert _inputs(inbox, 0.4)[-1]['accel_mps2'] == pytest.approx(-6.0, abs=0.2)
    page.mouse.up()
    # a gamepad's right trigger (the Gamepad API; a stand-in pad, headless has none)
    page.evaluate('window.fakePad = {buttons: Array.from({length: 8}, (_, i) => '
                  '({value: i === 7 ? 0.5 : 0})), axes: [0, 0]}')
    assert _inputs(inbox, 0.4)[-1]['accel_mps2'] == pytest.approx(1.25)


def test_rating_prompt_does_not_stop_the_input_and_reconnection_resumes(
        served: tuple[DriveServer, queue.Queue[dict[str, Any]]], page: Any) -> None:
    server, inbox = served
    _drive(server, page)
    server.send({'type': 'rate', 'id': 7})
    page.wait_for_selector('#rating:not([hidden])', timeout=5000)
    assert page.locator('#rating-submit').is_disabled()   # no default answer
    assert len(_inputs(inbox, 0.5)) >= 5                  # samples go on under the prompt
    page.locator('#rating-slider').fill('83')
    page.click('#rating-submit')
    ratings = []
    end = time.monotonic() + 5
    while not ratings and time.monotonic() < end:
        message = inbox.get(timeout=5)
        if message['type'] == 'rating':
            ratings.append(message)
    assert ratings[0]['value'] == 83 and ratings[0]['id'] == 7
    server.close_clients()                                # the connection is lost
    page.wait_for_function("document.getElementById('status').textContent"
                           ".includes('connection lost')", timeout=5000)
    server.send({'type': 'phase', 'phase': 'driving', 'duration_s': 60.0})
    page.wait_for_function('window.drive.ws.readyState === 1', timeout=10_000)
    server.send({'type': 'phase', 'phase': 'driving', 'duration_s': 60.0})
    assert _inputs(inbox, 1.0)                            # and the input comes back


KONVA_VERSION = '10.9.1'
"""The vendored Konva (src/trust_av/trust_av/drive/web/vendor/README.md)."""
LIT_PIXELS = """() => {
    const canvas = Array.from(document.querySelectorAll('#road .konvajs-content canvas'))
        .find((c) => c.style.display !== 'none');
    const data = canvas.getContext('2d').getImageData(0, 0, canvas.width, canvas.height).data;
    let lit = 0;
    const colours = new Set();
    for (let i = 0; i < data.length; i += 4) {
        if (data[i] > 200 && data[i + 1] < 90 && data[i + 2] < 90) lit++;
        colours.add((data[i] >> 4) * 256 + (data[i + 1] >> 4) * 16 + (data[i + 2] >> 4));
    }
    return [lit, colours.size]; }"""
"""Bright red pixels (a lit brake light) and distinct colours (4 bits a channel) on the
canvas the view shows."""


def _states(server: DriveServer, av_accel_mps2: float, seconds: float = 0.6) -> None:
    """State frames at 20 Hz, the AV 20 m ahead and commanded ``av_accel_mps2``."""
    for k in range(round(seconds * 20)):
        you = 100.0 + 0.5 * k
        server.send({'type': 'state', 't_s': k * 0.05, 'left_s': 50.0,
                     'vehicles': {'lead': [you + 60.0, 10.0], 'av': [you + 24.5, 10.0],
                                  'you': [you, 10.0]}, 'av_accel_mps2': av_accel_mps2})
        time.sleep(0.05)


def test_the_drivers_eye_view_is_drawn_by_the_vendored_library_from_the_page_s_origin(
        served: tuple[DriveServer, Any], browser: Any) -> None:
    server, _ = served
    tab = browser.new_page()
    requests: list[str] = []
    tab.on('request', lambda request: requests.append(request.url))
    tab.on('websocket', lambda socket: requests.append(socket.url))
    response = tab.goto(server.url)
    assert "default-src 'none'" in response.headers['content-security-policy']
    tab.wait_for_function('window.drive.ws && window.drive.ws.readyState === 1')
    # the view is a Konva stage (the vendored build, served by the drive server)
    assert tab.evaluate('Konva.version') == KONVA_VERSION
    assert tab.evaluate('drive.view.stage instanceof Konva.Stage && '
                        "drive.view.stage.container() === document.getElementById('road')")
    assert tab.evaluate("Array.from(document.querySelectorAll('#road canvas'))"   # no frame yet
                        ".every((c) => c.style.display === 'none')")
    server.send({'type': 'phase', 'phase': 'driving', 'duration_s': 60.0})
    tab.wait_for_function("window.drive.phase === 'driving'")
    _states(server, 0.0)
    dark, colours = tab.evaluate(LIT_PIXELS)
    assert colours > 20 and tab.evaluate('drive.view.driver.layer.isVisible()')
    # the AV commanded to brake: its brake lights are lit; released: dark again
    _states(server, -3.0)
    lit, _ = tab.evaluate(LIT_PIXELS)
    _states(server, 0.5)
    dark_again, _ = tab.evaluate(LIT_PIXELS)
    assert lit > 100 + 10 * max(dark, dark_again), (dark, lit, dark_again)
    # the view from above, still drawn with the library
    tab.check('#top-down')
    _states(server, 0.0, 0.3)
    assert tab.evaluate('drive.view.top.layer.isVisible() && !drive.view.driver.layer.isVisible()')
    assert tab.evaluate("Array.from(document.querySelectorAll('#road canvas'))"
                        ".filter((c) => c.style.display !== 'none').length") == 1
    assert tab.evaluate(LIT_PIXELS)[1] > 5
    # everything the page loaded or connected to is the drive server's
    origin = server.url.rstrip('/').removeprefix('http://')
    assert f'{server.url}vendor/konva/konva.min.js' in requests
    assert requests and all(url.split('/')[2] == origin for url in requests), requests
    tab.close()
