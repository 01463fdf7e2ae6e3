"""The drive page in headless chromium, against the drive's web server alone (no graph): its
inputs (keyboard ramps, the pointer pedal, a gamepad, stamped samples at the control rate),
the non-blocking rating and reconnection, and its view (drawn by the vendored Konva, the AV's
brake lights lit while it is commanded to brake, nothing loaded from another origin). The
state stream is played by the test."""

from __future__ import annotations

import itertools
import queue
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from support.paths import REPO

from trust_av.drive.server import DriveServer

sys.path.insert(0, str(REPO / 'benchmarks'))
from synthetic_participant import CHROMIUM, CHROMIUM_ARGS

pytestmark = [pytest.mark.wall_clock,
              pytest.mark.skipif(not Path(CHROMIUM).exists(),
                                 reason='Debian chromium not installed (scripts/bootstrap.sh)')]

RATE_HZ = 20.0
HELLO = {'type': 'hello', 'rating_period_s': 1.0, 'control_rate_hz': RATE_HZ,
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


def _inputs_until(inbox: queue.Queue[dict[str, Any]], seq: int,
                  timeout_s: float = 30.0) -> list[dict[str, Any]]:
    """The pedal samples that reached the server, up to and including the page's sample
    ``seq`` (the page numbers its samples; the timeout only bounds a failure)."""
    out: list[dict[str, Any]] = []
    while not out or out[-1]['seq'] < seq:
        message = inbox.get(timeout=timeout_s)
        if message['type'] == 'input':
            out.append(message)
    return out


def _sent(page: Any, inbox: queue.Queue[dict[str, Any]], condition: str) -> dict[str, Any]:
    """The page's newest sample once ``condition`` (on ``drive.lastSentPedal``, the pedal it
    last sent) holds, as the server received it."""
    page.wait_for_function(f'(p => {condition})(window.drive.lastSentPedal)')
    return _inputs_until(inbox, page.evaluate('window.drive.seq'))[-1]


def _drive(server: DriveServer, page: Any) -> None:
    server.send({'type': 'phase', 'phase': 'driving', 'duration_s': 60.0})
    page.wait_for_function("window.drive.phase === 'driving'")
    for k in range(5):      # a state stream, so the page has something to draw
        server.send({'type': 'state', 't_s': k * 0.1, 'trust': 0.5, 'vehicles': {
            'lead': [60.0 + k, 10.0], 'av': [30.0 + k, 10.0], 'you': [float(k), 10.0]}})
    page.wait_for_function("document.getElementById('gap').dataset.m !== undefined")


PERIOD_MS = 1000 / RATE_HZ


def test_keyboard_pointer_and_gamepad_drive_the_pedal(
        served: tuple[DriveServer, queue.Queue[dict[str, Any]]], page: Any) -> None:
    server, inbox = served
    _drive(server, page)
    assert page.locator('#gap').get_attribute('data-m') is not None
    # the gas key held until the pedal is full and a second's worth of samples went out,
    # counted by the page's own sample numbers and send times (t_ms), not a wall window
    before = _sent(page, inbox, 'p !== null')['seq']
    page.keyboard.down('ArrowUp')
    page.wait_for_function(f'window.drive.pedal >= 1 && window.drive.seq >= {before} + 20')
    held = page.evaluate('window.drive.seq')
    page.keyboard.up('ArrowUp')
    gas = [m for m in _inputs_until(inbox, held) if m['seq'] > before]
    assert [m['seq'] for m in gas] == list(range(before + 1, held + 1))   # none lost
    while gas[0]['accel_mps2'] == 0.0:     # a periodic sample sent just before the press
        gas.pop(0)
    accel = [m['accel_mps2'] for m in gas]
    # the press itself (0.15 of the pedal at once), then the ramp to full gas
    assert accel[0] == pytest.approx(0.15 * 2.5) and accel == sorted(accel)
    assert accel[-1] == 2.5
    # about one sample per control period on the page's clock while the key is held: no
    # two closer than the periodic tick allows (no flood), and the typical spacing a
    # period, whatever a late timer tick or two does
    gaps = np.diff([m['t_ms'] for m in gas])
    assert gaps.min() >= 0.8 * PERIOD_MS - 1.0, gaps
    assert 0.8 * PERIOD_MS <= float(np.median(gaps)) <= 1.5 * PERIOD_MS, gaps
    _sent(page, inbox, 'p === 0')                         # released: back to zero
    page.keyboard.down('KeyS')
    brake = _sent(page, inbox, 'p <= -0.6')
    page.keyboard.up('KeyS')
    assert brake['accel_mps2'] < -3.0
    # the press itself is sent at once, in the key's own event handler (not at the next
    # tick of the control rate): the page's sample number moves inside the keydown handler,
    # and that sample is gas (whatever the machine's load does to the timing of the above)
    _sent(page, inbox, 'p === 0')
    before, after = page.evaluate("""() => {
        const before = drive.seq;
        window.dispatchEvent(new KeyboardEvent('keydown', {code: 'KeyW'}));
        const after = drive.seq;
        window.dispatchEvent(new KeyboardEvent('keyup', {code: 'KeyW'}));
        return [before, after]; }""")
    assert after == before + 1
    pressed = {m['seq']: m['accel_mps2'] for m in _inputs_until(inbox, after)}
    assert pressed[after] > 0.0
    # the pointer pedal: held at the top is full gas, at the bottom full brake
    box = page.locator('#pedal').bounding_box()
    page.mouse.move(box['x'] + box['width'] / 2, box['y'] + 1)
    page.mouse.down()
    assert _sent(page, inbox, 'p > 0.95')['accel_mps2'] == pytest.approx(2.5, abs=0.1)
    page.mouse.move(box['x'] + box['width'] / 2, box['y'] + box['height'] - 1)
    assert _sent(page, inbox, 'p < -0.95')['accel_mps2'] == pytest.approx(-6.0, abs=0.2)
    page.mouse.up()
    # a gamepad's right trigger (the Gamepad API; a stand-in pad, headless has none)
    page.evaluate('window.fakePad = {buttons: Array.from({length: 8}, (_, i) => '
                  '({value: i === 7 ? 0.5 : 0})), axes: [0, 0]}')
    assert _sent(page, inbox, 'p === 0.5')['accel_mps2'] == pytest.approx(1.25)


def test_rating_prompt_does_not_stop_the_input_and_reconnection_resumes(
        served: tuple[DriveServer, queue.Queue[dict[str, Any]]], page: Any) -> None:
    server, inbox = served
    _drive(server, page)
    server.send({'type': 'rate', 'id': 7})
    page.wait_for_selector('#rating:not([hidden])', timeout=5000)
    assert page.locator('#rating-submit').is_disabled()   # no default answer
    # nor a bias toward one: no thumb until the scale is touched, and a click on the very
    # spot where it would stand (50, the middle: no value changes, no 'input' event) answers
    assert 'unset' in page.locator('#rating-slider').get_attribute('class')   # no thumb
    page.locator('#rating-slider').click()                # the middle of the scale
    assert page.locator('#rating-slider').input_value() == '50'
    assert page.locator('#rating-submit').is_enabled()
    assert page.locator('#rating-value').text_content() == '50'
    assert 'unset' not in page.locator('#rating-slider').get_attribute('class')
    # samples go on under the prompt: five more reach the server while it is open
    shown = page.evaluate('window.drive.seq')
    page.wait_for_function(f'window.drive.seq >= {shown} + 5')
    assert page.locator('#rating').is_visible()
    assert len([m for m in _inputs_until(inbox, shown + 5) if m['seq'] > shown]) >= 5
    page.locator('#rating-slider').fill('83')
    page.click('#rating-submit')
    message = inbox.get(timeout=10)
    while message['type'] != 'rating':
        message = inbox.get(timeout=10)
    assert message['value'] == 83 and message['id'] == 7
    close_clients(server)                                 # the connection is lost
    page.wait_for_function("document.getElementById('status').textContent"
                           ".includes('connection lost')", timeout=5000)
    lost = page.evaluate('window.drive.seq')
    page.wait_for_function('window.drive.ws.readyState === 1', timeout=10_000)
    server.send({'type': 'phase', 'phase': 'driving', 'duration_s': 60.0})
    page.wait_for_function(f'window.drive.seq > {lost}', timeout=10_000)
    assert _inputs_until(inbox, lost + 1)[-1]['seq'] == lost + 1   # and the input comes back


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


def _states(server: DriveServer, tab: Any, av_accel_mps2: float) -> None:
    """State frames at 20 Hz (0.3 s of them), the AV 20 m ahead and commanded
    ``av_accel_mps2``, until the page has drawn one (the view is drawn in the same frame
    as ``drive.displayed`` is set)."""
    for k in range(6):
        you = 100.0 + 0.5 * k
        server.send({'type': 'state', 't_s': k * 0.05, 'left_s': 50.0,
                     'vehicles': {'lead': [you + 60.0, 10.0], 'av': [you + 24.5, 10.0],
                                  'you': [you, 10.0]}, 'av_accel_mps2': av_accel_mps2})
        time.sleep(0.05)
    tab.wait_for_function('window.drive.displayed && window.drive.displayed.avAccel === '
                          f'{av_accel_mps2}')


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
    _states(server, tab, 0.0)
    dark, colours = tab.evaluate(LIT_PIXELS)
    assert colours > 20 and tab.evaluate('drive.view.driver.layer.isVisible()')
    # the AV commanded to brake: its brake lights are lit; released: dark again
    _states(server, tab, -3.0)
    lit, _ = tab.evaluate(LIT_PIXELS)
    _states(server, tab, 0.5)
    dark_again, _ = tab.evaluate(LIT_PIXELS)
    assert lit > 100 + 10 * max(dark, dark_again), (dark, lit, dark_again)
    # the view from above, still drawn with the library
    tab.check('#top-down')
    _states(server, tab, 0.0)
    tab.wait_for_function('drive.view.top.layer.isVisible()')
    assert tab.evaluate('drive.view.top.layer.isVisible() && !drive.view.driver.layer.isVisible()')
    assert tab.evaluate("Array.from(document.querySelectorAll('#road canvas'))"
                        ".filter((c) => c.style.display !== 'none').length") == 1
    assert tab.evaluate(LIT_PIXELS)[1] > 5
    # everything the page loaded or connected to is the drive server's
    origin = server.url.rstrip('/').removeprefix('http://')
    assert f'{server.url}vendor/konva/konva.min.js' in requests
    assert requests and all(url.split('/')[2] == origin for url in requests), requests
    tab.close()


def close_clients(server: DriveServer) -> None:
    """Drop every page connection, as a lost network does."""
    import asyncio

    loop = server._loop
    assert loop is not None
    for client in list(server.clients):
        asyncio.run_coroutine_threadsafe(client.close(), loop)


def _next(inbox: queue.Queue[dict[str, Any]], kind: str) -> dict[str, Any]:
    """The next message of type ``kind`` the page sent (others skipped)."""
    while True:
        message = inbox.get(timeout=30)
        if message['type'] == kind:
            return message


def test_the_continuous_scale_is_set_before_the_start_and_stays_while_driving() -> None:
    """rating_mode continuous: the scale sits on the start screen, unset, and Start waits for
    it; it stays on screen while driving and each move reaches the server as ``trust``, no
    more than one every 0.2 s and the last position always; a reopened page shows the
    position it had; the next drive's start screen asks again."""
    from playwright.sync_api import sync_playwright
    inbox: queue.Queue[dict[str, Any]] = queue.Queue()
    hello = {**HELLO, 'rating_mode': 'continuous', 'scale': None}
    server = DriveServer(lambda m, _ns: inbox.put(m), lambda: hello, port=0)
    server.start()
    try:
        with sync_playwright() as playwright:
            browser = playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
            tab = browser.new_page()
            tab.goto(server.url)
            tab.wait_for_function('window.drive.ws && window.drive.ws.readyState === 1')
            server.send({'type': 'phase', 'phase': 'ready', 'duration_s': 60.0})
            tab.wait_for_selector('#intro #rating:not([hidden])', timeout=10_000)
            assert 'unset' in tab.locator('#rating-slider').get_attribute('class')
            assert tab.locator('#start').is_disabled()
            assert not tab.locator('#rating-submit').is_visible()
            tab.locator('#rating-slider').click()            # the middle: an answer too
            assert _next(inbox, 'trust')['value'] == 50
            assert tab.locator('#start').is_enabled()
            tab.click('#start')
            assert _next(inbox, 'ready') == {'type': 'ready'}
            _drive(server, tab)
            tab.wait_for_selector('#stage #rating:not([hidden])', timeout=10_000)
            assert tab.locator('#rating-slider').input_value() == '50'
            # a drag of 17 moves, 6 ms apart when the host keeps up, with the page once busy for
            # 0.25 s while a send waits on its timer; checked on the page's own send times, so a
            # slow host changes how many sends there are, not the rule they keep
            sent = tab.evaluate("""async () => {
                const s = document.getElementById('rating-slider');
                const ws = drive.ws, raw = ws.send.bind(ws), times = [];
                ws.send = (data) => {
                    if (JSON.parse(data).type === 'trust') times.push(performance.now());
                    raw(data);
                };
                for (let v = 60; v <= 90; v += 2) {
                    s.value = v; s.dispatchEvent(new Event('input'));
                    if (v === 62) {         // a busy page: the deferred send's timer is due
                        const t = performance.now();       // but has not run when 63 comes
                        while (performance.now() - t < 250) {}
                        s.value = 63; s.dispatchEvent(new Event('input'));
                    }
                    await new Promise((r) => setTimeout(r, 6));
                }
                while (drive.trustTimer) await new Promise((r) => setTimeout(r, 20));
                return {scale: drive.scale, times: times}; }""")
            assert sent['scale'] == 90
            values = []
            while not values or values[-1] != 90:
                values.append(_next(inbox, 'trust')['value'])
            times = sent['times']
            assert len(values) == len(times), (values, times)
            # each send a newer position than the one before (none repeated), the last the
            # final one, and no two sends closer than the page's 0.2 s limit
            assert values == sorted(set(values)) and values[0] >= 60, values
            assert all(b - a >= 199.0 for a, b in itertools.pairwise(times)), times
            tab.close()
            hello['scale'] = 90                              # the server's kept position
            tab = browser.new_page()
            tab.goto(server.url)
            tab.wait_for_function('window.drive.ws && window.drive.ws.readyState === 1')
            server.send({'type': 'phase', 'phase': 'driving', 'duration_s': 60.0})
            tab.wait_for_selector('#stage #rating:not([hidden])', timeout=10_000)
            assert tab.locator('#rating-slider').input_value() == '90'
            assert 'unset' not in tab.locator('#rating-slider').get_attribute('class')
            server.send({'type': 'phase', 'phase': 'wait'})
            tab.wait_for_selector('#rating', state='hidden', timeout=10_000)
            server.send({'type': 'phase', 'phase': 'ready', 'duration_s': 60.0})
            tab.wait_for_selector('#intro #rating:not([hidden])', timeout=10_000)
            assert 'unset' in tab.locator('#rating-slider').get_attribute('class')
            assert tab.locator('#start').is_disabled()
            browser.close()
    finally:
        server.stop()
