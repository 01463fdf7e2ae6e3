"""A participant's misuse through the real page (Debian's chromium, headless, Playwright).

The impatient start, under both collision protocols of config/drive.yaml (``on_collision``):
the participant holds the gas on the start screen and keeps it held while the AV waits. The
car hits the AV and stops at its rear bumper, never through it; the page says so; with
``end`` the drive ends there (the page says why, the questionnaire follows), with
``continue`` it goes on to its time. The bag (events and ``custom_data``), the summary and
``session.json`` record the collision; every field the page was told is one it may show
(nothing about any model's trust).

Stray messages in every phase (start screen, driving, a prompt open, nodes stopping,
questionnaire, after the answers), sent on the driving tab's own connection: refused and
counted by reason, never stored, and the connection never fails. They share the
``continue`` drive (one drive, the gas held to its end), so the tier runs one drive less.
"""

from __future__ import annotations

import csv
import json
import re
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from support.drive_process import Drive
from support.paths import REPO
from support.rosbag2_rules import check_bag_directory

from trust_av.drive.bag_data import custom_data, read_drive
from trust_av.drive.gate import reason_key

sys.path.insert(0, str(REPO / 'benchmarks'))
from synthetic_participant import CHROMIUM

pytestmark = [pytest.mark.slow, pytest.mark.wall_clock,
              pytest.mark.skipif(not Path(CHROMIUM).exists(),
                                 reason='Debian chromium not installed (scripts/bootstrap.sh)')]

DRIVE_S = 25.0
"""The ``end`` drive's length (it ends at the collision, a few seconds in)."""
CONTINUE_DRIVE_S = 18.0
"""The ``continue`` drive's length: the collision, a rating prompt (every 3 s) and the
strays of each phase fit in it, also on a host three times slower than an idle one."""
VIEWPORT = {'width': 800, 'height': 680}
"""Small enough to draw cheaply (the page redraws its canvas every display frame: Chromium
takes most of a drive's CPU, less the smaller the canvas)."""
ANSWERS = [3, 2, 2, 3, 1, 5, 6, 5, 4, 6, 6, 4]
SETTINGS = """/**/drive:
  ros__parameters:
    drive_duration_s: {duration}
    practice: false
    rating_period_s: {rating_period_s}
    abandon_after_s: 8.0
    start_timeout_s: 120.0
    questionnaire_timeout_s: 60.0
    port: 0
    on_collision: {protocol}
    condition_names: [low_alpha]
    condition_alphas: [0.0]
    condition_predictors: [ca]
    condition_traces: [us06]
"""
WATCH_MESSAGES = """() => {
    window.shown = [];
    const note = () => {
        for (const id of ['crash', 'message']) {
            const el = document.getElementById(id);
            if (!el.hidden && !window.shown.includes(el.textContent)) {
                window.shown.push(el.textContent);
            }
        }
    };
    new MutationObserver(note).observe(document.body, {subtree: true, childList: true,
        attributes: true, characterData: true});
}"""
"""Everything the crash card and the message card showed, as it showed (a card may be
replaced before a poll would see it)."""
RECORD_RECEIVED = """(() => {
    window.received = {};
    const Native = window.WebSocket;
    window.WebSocket = function (...args) {
        const ws = new Native(...args);
        ws.addEventListener('message', (event) => {
            const msg = JSON.parse(event.data);
            const keys = window.received[msg.type] = window.received[msg.type] || [];
            for (const key of Object.keys(msg)) if (!keys.includes(key)) keys.push(key);
        });
        return ws;
    };
    Object.assign(window.WebSocket, Native);
})();"""
"""Every field of every message type the page receives."""
PAGE_FIELDS = {
    'hello': {'type', 'control_rate_hz', 'input_burst', 'participant', 'accel_max_mps2',
              'accel_min_mps2', 'on_collision', 'rating_mode', 'prompts', 'scale', 'phase',
              'duration_s', 'practice', 'number', 'of'},
    'control': {'type', 'controlling', 'other', 'taken_over'},
    'phase': {'type', 'phase', 'duration_s', 'practice', 'number', 'of', 'ended_by', 'items'},
    'state': {'type', 't_s', 'left_s', 'vehicles', 'av_accel_mps2', 'collisions', 'crash',
              'ack'},
    'rate': {'type', 'id'}}
"""What the page may be told (docs/concepts/driver-in-the-loop.md, The page): the vehicles,
the AV's commanded acceleration, the time left, collisions, the phase, how the study rates
and the participant's own scale position (for a reopened tab); nothing about any model's
trust."""


def _events(bag: Path) -> list[tuple[str, dict[str, str]]]:
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        connections = [c for c in reader.connections if c.topic == '/driver/events']
        out = []
        for c, _, raw in reader.messages(connections=connections):
            msg: Any = reader.deserialize(raw, c.msgtype)
            status = msg.status[0]
            out.append((status.message, {v.key: v.value for v in status.values}))
        return out


def _start_with_the_gas_held(page: Any, drive: Drive, *, strays: bool) -> None:
    """Open the page, watch its cards, hold the gas on the start screen and start (the
    strays on the start screen first, and again when the drive waits and the
    questionnaire opens, if ``strays``)."""
    page.add_init_script(RECORD_RECEIVED)
    page.goto(drive.url)
    page.wait_for_selector('#start', state='visible', timeout=120_000)
    page.evaluate(WATCH_MESSAGES)
    if strays:
        page.wait_for_function('window.drive.controlling', timeout=30_000)
        page.evaluate(STRAYS, 'ready')
        page.wait_for_timeout(1000)
        assert page.evaluate('window.drive.phase') == 'ready'     # nothing started it
        page.evaluate(STRAYS_ON_PHASE, STRAYS)
    page.keyboard.down('ArrowUp')               # impatient: the gas before the start
    page.click('#start')


def _answer(page: Any) -> list[str]:
    """The gas released, the questionnaire answered; what the cards showed."""
    page.keyboard.up('ArrowUp')
    shown: list[str] = page.evaluate('window.shown')
    for i, value in enumerate(ANSWERS):
        page.check(f'input[name="item{i + 1}"][value="{value}"]')
    page.click('#questionnaire-submit')
    return shown


def _check_the_collision(study: Path, output: str, protocol: str, shown: list[str],
                         received: dict[str, list[str]], duration_s: float) -> Path:
    """What the page was told and showed, and what the session, summary and bag recorded,
    for a drive started with the gas held; the bag."""
    # the page was told nothing it should not show (no model's trust), and it was told
    # the collision and the state
    assert set(received) <= set(PAGE_FIELDS), received
    for kind, fields in received.items():
        assert set(fields) <= PAGE_FIELDS[kind], (kind, fields)
    assert {'vehicles', 'crash', 'collisions'} <= set(received['state'])
    drives_on = 'Your car hit the AV and stopped behind it. Drive on when the AV moves away.'
    ended = 'The drive ended: your car hit the AV. Please wait a moment.'
    seen = ' | '.join(shown)
    if protocol == 'end':
        assert ended in seen and drives_on not in seen, shown
    else:
        assert drives_on in seen and ended not in seen, shown
    assert re.search(r'drive 1 \(low_alpha\): done after [0-9.]+ s, [1-9]\d* collisions',
                     output), output
    session = json.loads((study / 'P09' / 'session.json').read_text())
    (record,) = session['drives']
    summary = record['summary']
    assert record['status'] == 'done' and summary['collisions'] >= 1
    assert summary['ended_by'] == ('collision' if protocol == 'end' else 'time')
    if protocol == 'end':
        assert summary['driven_s'] < duration_s - 5.0
    else:
        assert summary['driven_s'] >= duration_s - 0.5
    with (study / 'P09' / 'summary.csv').open() as table:
        (row,) = list(csv.DictReader(table))
    assert int(row['collisions']) == summary['collisions']
    assert row['ended_by'] == summary['ended_by']
    assert float(row['min_gap_m']) > -0.2
    bag: Path = study / record['bag']
    assert check_bag_directory(bag) == []
    meta = custom_data(bag)
    assert meta['trust_av.drive.on_collision'] == protocol
    assert meta['trust_av.drive.ended_by'] == summary['ended_by']
    assert int(meta['trust_av.drive.collisions']) == summary['collisions']
    events = _events(bag)
    kinds = [kind for kind, _ in events]
    first = kinds.index('collision')
    assert kinds.index('start') < first < kinds.index('end')
    assert events[first][1] == {'count': '1', 'protocol': protocol}
    assert events[kinds.index('end')][1]['ended_by'] == summary['ended_by']
    # the car never went through the AV, and it was held there by the gas, not by luck
    data = read_drive(bag)
    you, av = data.odometry['/human/odom'], data.odometry['/ego/odom']
    # while both are recorded (as the nodes stop, the AV's odometry may end first)
    you = you[you[:, 0] <= av[-1, 0]]
    gaps = np.interp(you[:, 0], av[:, 0], av[:, 1]) - 4.5 - you[:, 1]
    assert gaps.min() > -0.2
    assert gaps.min() < 0.5
    assert data.questionnaire[:12] == ANSWERS
    return bag


def test_gas_held_at_the_start_hits_the_av_and_the_end_protocol_ends_the_drive(
        tmp_path: Path, browser: Any) -> None:
    settings = tmp_path / 'drive.yaml'
    settings.write_text(SETTINGS.format(duration=DRIVE_S, protocol='end', rating_period_s=60.0))
    study = tmp_path / 'study'
    drive = Drive(study, 'P09', settings, practice=True)
    try:
        page = browser.new_page(viewport=VIEWPORT)
        _start_with_the_gas_held(page, drive, strays=False)
        # the drive ends at once: the page says why, then asks
        page.wait_for_function("window.drive.phase === 'questionnaire'", timeout=90_000)
        shown = _answer(page)
        page.wait_for_function("window.drive.phase === 'finished'", timeout=60_000)
        received = page.evaluate('window.received')
        output = drive.finish()
    finally:
        drive.kill()
    _check_the_collision(study, output, 'end', shown, received, DRIVE_S)


STRAYS = """(phase) => {
    const ws = window.drive.ws, huge = '9'.repeat(400);
    const raw = [
        JSON.stringify({type: 'input', seq: 1, accel_mps2: 2.0}),
        JSON.stringify({type: 'rating', id: 999, value: 100}),
        JSON.stringify({type: 'trust', value: 50}),     // a continuous study's scale
        JSON.stringify({type: 'ack', seq: 1}),
        JSON.stringify({type: 'take_over'}),
        JSON.stringify({type: 'hello'}), JSON.stringify({type: 'state'}), '[1, 2]', 'null',
        `{"type": "input", "seq": 2, "accel_mps2": ${huge}}`,
        `{"type": "rating", "id": ${window.drive.prompt || 1}, "value": ${huge}}`,
        JSON.stringify({type: 'rating', id: window.drive.prompt || 1, value: 'NaN'}),
        JSON.stringify({type: 'input', seq: 3, accel_mps2: true}),
        JSON.stringify({type: 'questionnaire', answers: [...Array(12).fill(8)]}),
        JSON.stringify({type: 'questionnaire', answers: 'seven'}),
        '{"type": "input", "accel_mps2": ' + '['.repeat(2000) + ']'.repeat(2000) + '}',
    ];
    // what fits the phase is not a stray: a start on the start screen, answers while the
    // questionnaire is open (a script in the page can give them, as the participant can)
    if (phase !== 'ready') raw.push(JSON.stringify({type: 'ready'}));
    if (phase !== 'questionnaire') {
        raw.push(JSON.stringify({type: 'questionnaire', answers: Array(12).fill(7)}));
    }
    for (const text of raw) ws.send(text);
    ws.send(new Uint8Array([0xff, 0xfe, 0x00]));
    window.strays = (window.strays || []).concat([phase]);
}"""
"""Every kind of message, well-formed or not, that does not belong (sent from the driving
tab's own connection: what a script in the participant's page can send)."""
STRAYS_ON_PHASE = """(send) => {
    const strays = eval(send);
    window.drive.ws.addEventListener('message', (event) => {
        const msg = JSON.parse(event.data);
        if (msg.type === 'phase' && ['wait', 'questionnaire'].includes(msg.phase)) {
            strays(msg.phase);
        }
    });
}"""
"""The strays again the moment the page is told the drive waits for its nodes to stop, and
the moment the questionnaire opens (before the participant answers)."""


def test_gas_held_under_the_continue_protocol_drives_on_and_strays_in_every_phase_are_refused(
        tmp_path: Path, browser: Any) -> None:
    settings = tmp_path / 'drive.yaml'
    settings.write_text(SETTINGS.format(duration=CONTINUE_DRIVE_S, protocol='continue',
                                        rating_period_s=3.0))
    study = tmp_path / 'study'
    drive = Drive(study, 'P09', settings, practice=True)
    try:
        page = browser.new_page(viewport=VIEWPORT)
        _start_with_the_gas_held(page, drive, strays=True)
        # the crash card showed (WATCH_MESSAGES keeps what it showed: the card shows for 3 s,
        # which a poll of its visibility on a starved page can miss; beside four busy
        # processes the follower hit the AV 2.4 s in and a visibility wait saw no card)
        page.wait_for_function("window.shown.some(text => text.includes('hit the AV'))",
                               timeout=60_000)
        # the car stopped at the AV's bumper (the page's own gap, never through it)
        assert float(page.locator('#gap').get_attribute('data-m')) > -0.1
        # the drive goes on, the gas still held: driving until its time is up
        assert page.evaluate('window.drive.phase') == 'driving'
        page.evaluate(STRAYS, 'driving')
        page.wait_for_selector('#rating', state='visible', timeout=30_000)
        page.evaluate(STRAYS, 'driving with a prompt open')
        page.locator('#rating-slider').fill('35')
        page.click('#rating-submit')
        page.wait_for_function("window.drive.phase === 'questionnaire'",
                               timeout=(CONTINUE_DRIVE_S + 60) * 1000)
        page.wait_for_function('window.strays.length === 5', timeout=10_000)
        shown = _answer(page)
        page.evaluate(STRAYS, 'after the answers')
        page.wait_for_function("window.drive.phase === 'finished'", timeout=60_000)
        received = page.evaluate('window.received')
        output = drive.finish()
    finally:
        drive.kill()
    bag = _check_the_collision(study, output, 'continue', shown, received, CONTINUE_DRIVE_S)
    assert page.evaluate('window.strays') == ['ready', 'driving', 'driving with a prompt open',
                                              'wait', 'questionnaire', 'after the answers']
    (record,) = json.loads((study / 'P09' / 'session.json').read_text())['drives']
    meta = custom_data(bag)
    refused = {k.removeprefix('trust_av.drive.refused.'): int(v) for k, v in meta.items()
               if k.startswith('trust_av.drive.refused.')}
    assert sum(refused.values()) == int(meta['trust_av.drive.refused']) \
        == record['summary']['refused_messages']
    for reason in ('input during ready', 'rating during ready', 'questionnaire during ready',
                   'ack during ready', 'questionnaire during driving', 'ready during driving',
                   'rating outside a prompt', 'rating not in [0, 100]',
                   'input without a finite accel_mps2', 'ack of no sent frame',
                   'input during wait', 'questionnaire during wait', 'ready during wait',
                   'input during questionnaire', 'rating during questionnaire',
                   'ready during questionnaire', 'questionnaire with bad answers',
                   'trust without the continuous rating', 'trust during wait',
                   'trust during questionnaire'):
        assert refused.get(reason_key(reason), 0) >= 1, (reason, refused)
    # 4 non-objects or unknown types, the deep nesting and the binary frame, 6 times (the
    # last time the page may have closed its connection on the end screen)
    assert 5 * 6 <= refused[reason_key('not a page message')] <= 6 * 6
    # nothing refused was stored, and the connection never failed
    data = read_drive(bag)
    assert data.questionnaire[:12] == ANSWERS
    np.testing.assert_allclose(data.ratings, [0.35])
    kinds = [kind for kind, _ in _events(bag)]
    assert 'page_lost' not in kinds and kinds.count('start') == 1
