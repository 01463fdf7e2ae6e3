"""A synthetic participant for the driver-in-the-loop page, driven through Playwright
(``bench_drive.py`` and the browser tests; not part of the packages: nothing in them drives
the page; Playwright is not imported here: the caller passes its page).

It reads the state the page itself displays (``#gap``, ``#speed``, ``#av-speed``: their
``data-`` values), computes its pedal with an IDM (Treiber & Kesting's motorway parameters,
with the harder acceleration and braking a US06 cycle needs) and holds the page's pointer
pedal at the matching height with the mouse, as a person with a mouse would; it answers each
trust rating with the slider and the questionnaire with the radio buttons.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

from human_driver_sim.idm import IdmParams, idm_accel

__all__ = ['CHROMIUM', 'CHROMIUM_ARGS', 'DRIVER', 'READ_DISPLAY', 'Participant', 'drive_once',
           'press_start']

CHROMIUM = '/usr/bin/chromium'
CHROMIUM_ARGS = ['--headless', '--no-sandbox', '--disable-gpu', '--disable-quic',
                 '--no-first-run', '--disable-background-networking',
                 '--disable-component-update', '--disable-sync']
READ_DISPLAY = """() => ({
    phase: window.drive.phase,
    gap: document.getElementById('gap').dataset.m,
    speed: document.getElementById('speed').dataset.mps,
    av: document.getElementById('av-speed').dataset.mps,
    max: window.drive.accelMax, min: window.drive.accelMin,
    continuous: window.drive.ratingMode === 'continuous',
    rating: window.drive.ratingMode !== 'continuous'
        && !document.getElementById('rating').hidden})"""
"""The displayed gap (m), own and AV speed (m/s), the pedal's range, whether the study rates
on the continuous scale and whether the rating card is open, as the page shows them."""
SCALE_MOVE_S = 10.0
"""On the continuous scale, the participant moves it this often (between ``rating`` and
``rating`` - 10)."""
DRIVER = IdmParams(desired_speed_mps=36.0, time_headway_s=1.2, min_gap_m=3.0,
                   max_accel_mps2=2.0, comfort_decel_mps2=2.5)


@dataclass
class Participant:
    """What the synthetic participant did."""

    ratings: list[int] = field(default_factory=list)
    questionnaires: int = 0
    pedal_moves: int = 0


def pedal_height(accel_mps2: float, accel_max: float, accel_min: float) -> float:
    """The pedal value in [-1, 1] for an acceleration (the page's mapping inverted)."""
    if accel_mps2 >= 0:
        return min(1.0, accel_mps2 / accel_max)
    return max(-1.0, -accel_mps2 / accel_min)


def press_start(page: Any, rating: int) -> bool:
    """Press the start screen's Start, setting the continuous scale to ``rating`` first
    when the study rates continuously (Start waits for it); whether it was set."""
    continuous = bool(page.evaluate("window.drive.ratingMode === 'continuous'"))
    if continuous:
        page.locator('#rating-slider').fill(str(rating))
    page.click('#start')
    return continuous


def drive_once(page: Any, who: Participant, *, rating: int = 70, until_s: float = 120.0,
               stop_after_s: float | None = None, answers: list[int] | None = None) -> str:
    """Start the drive shown on the page, drive it, rate, answer the questionnaire.

    Args:
        page: a Playwright page showing the drive.
        who: the participant's record (appended to).
        rating: the rating given each time the prompt shows (on the continuous scale: set
            on the start screen, then moved to ``rating`` - 10 and back every
            :data:`SCALE_MOVE_S`).
        until_s: give up after this long.
        stop_after_s: stop driving (return) this long after the start, with the pedal held
            (the caller then closes the tab or cuts the connection).
        answers: the 12 questionnaire answers.

    Returns:
        The page's status text when it returned.
    """
    page.wait_for_selector('#start:not([hidden])', timeout=until_s * 1000)
    if press_start(page, rating):
        who.ratings.append(rating)
    page.wait_for_function("window.drive.phase === 'driving'", timeout=30_000)
    box = page.locator('#pedal').bounding_box()
    x = box['x'] + box['width'] / 2
    page.mouse.move(x, box['y'] + box['height'] / 2)
    page.mouse.down()
    started = time.monotonic()
    deadline = started + until_s
    moved = started
    while time.monotonic() < deadline:
        # what the page displays, read in one call (a person looks once, not five times)
        seen = page.evaluate(READ_DISPLAY)
        phase = str(seen['phase'])
        if phase != 'driving':
            break
        if stop_after_s is not None and time.monotonic() - started > stop_after_s:
            return phase
        if seen['gap'] and seen['speed'] and seen['av']:
            accel = idm_accel(DRIVER, float(seen['gap']), float(seen['speed']),
                              float(seen['av']))
            value = pedal_height(accel, float(seen['max']), float(seen['min']))
            page.mouse.move(x, box['y'] + box['height'] * (1 - value) / 2)
            who.pedal_moves += 1
        if seen['continuous'] and time.monotonic() - moved >= SCALE_MOVE_S:
            moved = time.monotonic()
            value = rating - 10 if who.ratings[-1:] == [rating] else rating
            page.mouse.up()          # one hand: let go of the pedal for a moment
            page.locator('#rating-slider').fill(str(value))
            who.ratings.append(value)
            page.mouse.move(x, box['y'] + box['height'] / 2)
            page.mouse.down()
        if seen['rating']:
            page.mouse.up()          # one hand: let go of the pedal for a moment
            page.locator('#rating-slider').fill(str(rating))
            page.click('#rating-submit')
            who.ratings.append(rating)
            page.mouse.move(x, box['y'] + box['height'] / 2)
            page.mouse.down()
        page.wait_for_timeout(100)   # about one look per control period
    page.mouse.up()
    page.wait_for_function("['questionnaire', 'ready', 'finished', 'paused']"
                           '.includes(window.drive.phase)', timeout=60_000)
    if page.evaluate('window.drive.phase') == 'questionnaire':
        for i, value in enumerate(answers or [2, 2, 1, 3, 1, 5, 5, 6, 5, 5, 6, 4]):
            page.check(f'input[name="item{i + 1}"][value="{value}"]')
        page.click('#questionnaire-submit')
        who.questionnaires += 1
    return str(page.evaluate('window.drive.phase'))
