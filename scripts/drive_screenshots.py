"""The drive page's screenshots in docs/images (drive-start, drive-page, drive-collision,
drive-rating, drive-questionnaire): the real page, served by the drive's own server
(``trust_av.drive.server.DriveServer``, no graph) and shown in headless Debian Chromium,
with the messages a drive sends played by this script: a car following the AV at about
60 km/h while the AV brakes (brake lights lit), a rating prompt, a collision, the
questionnaire.

Usage: python scripts/drive_screenshots.py [--out docs/images] [--top-down]
(``--top-down`` also writes drive-top-down.png, the view from above.)
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from trust_av.drive.gate import INPUT_BURST
from trust_av.drive.server import DriveServer
from trust_av.drive.trust_rating import JIAN_ITEMS

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / 'benchmarks'))
from synthetic_participant import CHROMIUM, CHROMIUM_ARGS  # noqa: E402

HELLO = {'type': 'hello', 'control_rate_hz': 10.0, 'input_burst': INPUT_BURST,
         'accel_max_mps2': 2.5, 'accel_min_mps2': -6.0, 'on_collision': 'continue'}
READY = {'type': 'phase', 'phase': 'ready', 'duration_s': 120.0, 'practice': False,
         'number': 1, 'of': 2}


def stream(server: DriveServer, seconds: float, gap_m: float, av_accel_mps2: float,
           speed_mps: float = 17.8, crash: bool = False) -> None:
    """State frames at 20 Hz for ``seconds``: you at ``speed_mps``, the AV ``gap_m`` ahead
    at 1.2 m/s slower, commanded ``av_accel_mps2``, the lead 30 m ahead of the AV."""
    t0 = time.monotonic()
    while (t := time.monotonic() - t0) < seconds:
        you = 200.0 + speed_mps * t
        av = you + gap_m + 4.5
        server.send({'type': 'state', 't_s': t, 'left_s': 26.4 - t,
                     'vehicles': {'lead': [av + 34.5, speed_mps - 0.8],
                                  'av': [av, max(0.0, speed_mps - 1.2)],
                                  'you': [you, speed_mps]},
                     'av_accel_mps2': av_accel_mps2, 'collisions': int(crash), 'crash': crash})
        time.sleep(0.05)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--out', type=Path, default=REPO / 'docs' / 'images')
    parser.add_argument('--top-down', action='store_true')
    args = parser.parse_args(argv)
    from playwright.sync_api import sync_playwright
    server = DriveServer(lambda _m, _ns: None, lambda: HELLO, port=0)
    server.start()
    try:
        with sync_playwright() as playwright:
            browser = playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
            page = browser.new_page(viewport={'width': 1000, 'height': 760})
            page.goto(server.url)
            page.wait_for_function('window.drive.ws && window.drive.ws.readyState === 1')
            server.send(READY)
            page.wait_for_selector('#intro:not([hidden])')
            page.screenshot(path=args.out / 'drive-start.png')
            page.click('#start')
            server.send({'type': 'phase', 'phase': 'driving', 'duration_s': 120.0})
            page.wait_for_function("window.drive.phase === 'driving'")
            stream(server, 1.5, 25.7, -2.4)
            page.screenshot(path=args.out / 'drive-page.png')
            if args.top_down:
                page.check('#top-down')
                stream(server, 0.5, 25.7, -2.4)
                page.screenshot(path=args.out / 'drive-top-down.png')
                page.uncheck('#top-down')
            server.send({'type': 'rate', 'id': 1})
            page.wait_for_selector('#rating:not([hidden])')
            stream(server, 0.5, 18.0, 0.2)
            page.locator('#rating-slider').fill('72')
            stream(server, 0.3, 18.0, 0.2)
            page.screenshot(path=args.out / 'drive-rating.png')
            page.click('#rating-submit')
            stream(server, 1.0, 0.0, -3.0, speed_mps=0.0, crash=True)
            page.screenshot(path=args.out / 'drive-collision.png')
            server.send({'type': 'phase', 'phase': 'questionnaire', 'items': list(JIAN_ITEMS)})
            page.wait_for_selector('#questionnaire:not([hidden])')
            page.screenshot(path=args.out / 'drive-questionnaire.png')
            browser.close()
    finally:
        server.stop()
    for name in ('start', 'page', 'rating', 'collision', 'questionnaire'):
        print(args.out / f'drive-{name}.png')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
