"""Driver in the loop through the real page: Debian's chromium, headless, driven by
Playwright; ``trust-av drive`` runs the node graph in wall mode and serves the page. A
synthetic participant (benchmarks/synthetic_participant.py: an IDM computing its pedal from the
page's own displayed state, held on the page's pointer pedal) drives whole sessions.

Checked: the bags hold every topic, the ratings and the questionnaire are recorded on the
drive's clock beside the monitor's trust, the study metadata is in ``custom_data``, the
comparison and the summary are written; a lost connection mid-drive (the practice drive's:
the page reconnects), a closed tab (the follower holds, coasts, brakes; the drive is
abandoned, its bag finished; the same command resumes the session) and a killed command
(the session resumes, the killed attempt kept) behave as docs/concepts/driver-in-the-loop.md
says. Each drive runs the node graph in wall time, so cases that can share a session do.
No timing assertion: the latency figures are the benchmark's (benchmarks/bench_drive.py).
"""

from __future__ import annotations

import json
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from support.drive_process import Drive
from support.paths import REPO
from support.rosbag2_rules import check_bag_directory

from trust_av.drive.bag_data import (
    DriveBagError,
    custom_data,
    demonstration,
    drive_bag_pairs,
    read_drive,
)
from trust_av.drive.gate import reason_key
from trust_av.drive.sessions import balanced_latin_square_row
from trust_av.drive.trust_rating import questionnaire_score
from trust_av_common.registry import names
from trust_monitor.model_interface import TRUST_MODELS

sys.path.insert(0, str(REPO / 'benchmarks'))
from synthetic_participant import CHROMIUM, Participant, drive_once

pytestmark = [pytest.mark.slow, pytest.mark.wall_clock,
              pytest.mark.skipif(not Path(CHROMIUM).exists(),
                                 reason='Debian chromium not installed (scripts/bootstrap.sh)')]

DRIVE_S = 10.0
"""The drive that resumes the closed tab's session, driven to its end and rated."""
LONG_DRIVE_S = 300.0
"""The closed tab's drive and the killed one: each ends by what the test does (ABANDON_S after
the tab closes, or the kill), never by its length, however slowly a loaded host runs the page
(with 10 s, the tab closed 2 s in on the page's clock missed the end on a host whose page lagged
by a second)."""
ABANDON_S = 5.0
"""No sample for this long abandons a drive: longer than the page's reconnection (1 s)."""
RATING_S = 2.0
SESSION_DRIVE_S = 10.0
"""The synthetic session's drives: four rating prompts each, two answers asked for (with 7 s
and three prompts, a drive beside the whole suite on a slow host got one answer in)."""
PRACTICE_S = 12.0
"""The synthetic session's practice drive: its connection lost half a second in, back a second
or two later, driven on and rated. Each step waits on the page, not on a window, but the drive
itself ends on time: everything up to the rating must fit in it, with room for a host that runs
the page three times slower than an idle one (the reconnection alone waits 1 s)."""
VIEWPORT = {'width': 800, 'height': 680}
"""Small enough to draw cheaply (the page redraws its canvas every display frame while
driving: Chromium takes most of a drive's CPU, less the smaller the canvas), tall enough for
the pedal and the questionnaire."""
ANSWERS = [2, 1, 2, 3, 1, 5, 6, 5, 5, 6, 6, 4]
SETTINGS = """/**/drive:
  ros__parameters:
    drive_duration_s: {drive_s}
    practice: true
    practice_duration_s: {practice_s}
    rating_period_s: {rating_s}
    abandon_after_s: {abandon_s}
    start_timeout_s: 120.0
    questionnaire_timeout_s: 60.0
    port: 0
    condition_names: [low_alpha, high_alpha]
    condition_alphas: [0.0, 1.0]
    condition_predictors: [ca, ca]
    condition_traces: [us06, us06]
"""


def _messages(bag: Path, topic: str) -> list[Any]:
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        connections = [c for c in reader.connections if c.topic == topic]
        return [reader.deserialize(raw, c.msgtype)
                for c, _, raw in reader.messages(connections=connections)]


def _counts(bag: Path) -> dict[str, int]:
    import yaml
    meta = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    return {t['topic_metadata']['name']: t['message_count']
            for t in meta['topics_with_message_count']}


def _stamp_ns(msg: Any) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


def _phases(bag: Path) -> list[str]:
    return [m.status[0].message for m in _messages(bag, '/human/driver_status')]


def test_a_synthetic_participant_completes_a_session_through_the_page(
        tmp_path: Path, browser: Any) -> None:
    settings = tmp_path / 'drive.yaml'
    settings.write_text(SETTINGS.format(drive_s=SESSION_DRIVE_S, practice_s=PRACTICE_S,
                                        rating_s=RATING_S, abandon_s=ABANDON_S))
    study = tmp_path / 'study'
    drive = Drive(study, 'P01', settings, practice=True)
    who = Participant()
    try:
        page = browser.new_page(viewport=VIEWPORT)
        page.goto(drive.url)
        page.wait_for_selector('#start:not([hidden])', timeout=120_000)
        assert page.text_content('#title') == 'Practice drive'
        # the practice drive: the connection drops as soon as it drives; the page reconnects
        # and the drive goes on (the participant lets go of the pedal), and the rating asked
        # for (before the drop or after it: the server asks again) is answered
        drive_once(page, who, rating=70, stop_after_s=0.5)
        page.mouse.up()
        page.evaluate('window.drive.ws.close()')
        page.wait_for_function("window.drive.phase === 'driving' && window.drive.ws"
                               '.readyState === 1 && window.drive.inputTimer !== null',
                               timeout=30_000)
        if not who.ratings:
            page.wait_for_selector('#rating', state='visible', timeout=30_000)
            page.locator('#rating-slider').fill('70')
            page.click('#rating-submit')
            who.ratings.append(70)
        for _ in range(2):
            assert drive_once(page, who, rating=70, answers=ANSWERS) in ('ready', 'finished',
                                                                          'questionnaire')
        page.wait_for_function("window.drive.phase === 'finished'", timeout=120_000)
        output = drive.finish()
    finally:
        drive.kill()
    session = json.loads((study / 'P01' / 'session.json').read_text())
    assert session['order'] == [['low_alpha', 'high_alpha'][i]
                                for i in balanced_latin_square_row(2, 0)]
    assert [d['condition'] for d in session['drives']] == ['practice', *session['order']]
    assert [d['status'] for d in session['drives']] == ['done', 'done', 'done']
    assert who.questionnaires == 2 and len(who.ratings) >= 5
    ratings_recorded = 0
    for record in session['drives']:
        bag = study / record['bag']
        assert check_bag_directory(bag) == []
        counts = _counts(bag)
        practice = record['condition'] == 'practice'
        # the recording's loss account, in the bag and in the session (0 on a clean drive)
        assert int(custom_data(bag)['trust_av.recording.lost']) == \
            record['summary']['recording_lost'] == \
            sum(int(n.split()[-3]) for n in record['summary']['recording_losses'])
        # every topic holds messages (the practice drive has no questionnaire)
        assert all(n for t, n in counts.items() if t != '/driver/questionnaire'), counts
        assert counts['/driver/questionnaire'] == (0 if practice else 1)
        if practice:
            ratings_recorded += counts['/driver/rating']
            # the lost connection: the follower held, coasted while the page was gone, and
            # the page drove again after (its samples held the pedal at zero)
            phases = _phases(bag)
            assert 'hold' in phases[phases.index('coast'):]
            assert custom_data(bag)['trust_av.drive.status'] == 'done'
            continue
        meta = custom_data(bag)
        assert meta['trust_av.participant'] == 'P01'
        assert meta['trust_av.condition'] == record['condition']
        assert meta['trust_av.seed'] == str(record['seed'])
        assert meta['trust_av.code_version'] and meta['trust_av.drive.status'] == 'done'
        assert int(meta['trust_av.drive.latency.samples']) > 0
        drive_data = read_drive(bag)
        assert len(drive_data.ratings) == counts['/driver/rating'] >= 2
        ratings_recorded += len(drive_data.ratings)
        np.testing.assert_allclose(drive_data.ratings, 0.70)
        assert drive_data.questionnaire[:12] == ANSWERS
        assert drive_data.questionnaire[12] == pytest.approx(questionnaire_score(ANSWERS))
        # the ratings sit on the drive's clock, inside the drive, beside the monitor's trust
        # (one may be given as the nodes stop)
        assert drive_data.rating_times_s.min() > 0
        assert drive_data.rating_times_s.max() < SESSION_DRIVE_S + 5.0
        assert np.isfinite(drive_data.series.monitor_trust).any()
        # the person drove: the follower moved, and the drive is a demonstration for the fit
        you = drive_data.odometry['/human/odom']
        assert you[:, 2].max() > 1.0          # from standstill (US06 starts slowly)
        pair = demonstration(drive_data, 1.0, 4.5)
        assert len(pair.gap_m) >= SESSION_DRIVE_S - 2 and pair.driver == 'drive:P01'
    assert ratings_recorded == len(who.ratings)
    comparison = (study / 'P01' / 'comparison.csv').read_text().splitlines()
    assert comparison[0].startswith('drive,condition,model,ratings,rmse,correlation')
    # every registered trust model, for each of the two drives
    models = names(TRUST_MODELS)
    assert len(comparison) == 1 + 2 * len(models)
    assert sorted(line.split(',')[2] for line in comparison[1:]) == sorted(models * 2)
    summary = (study / 'P01' / 'summary.csv').read_text().splitlines()
    assert len(summary) == 4 and all(',done,' in line for line in summary[1:])
    assert 'rmse' in output and 'paper' in output
    # trust-av fit-driver --drives: two complete drives cannot fill train, validation and
    # test; the refusal names the count (the split itself: test_drive_core)
    with pytest.raises(DriveBagError,
                       match='at least three drives to train, validate and test, got 2'):
        drive_bag_pairs(study, 1.0, 4.5)


def test_a_closed_tab_and_a_killed_command_leave_a_session_that_resumes(
        tmp_path: Path, browser: Any) -> None:
    """A closed tab: the drive is abandoned, its bag finished; the same command resumes the
    session with that condition; killed during that drive (nothing finished), the command
    again resumes it, the killed attempt kept; a stop signal on a start screen ends it."""
    import signal
    long_settings = tmp_path / 'drive_long.yaml'
    long_settings.write_text(SETTINGS.format(drive_s=LONG_DRIVE_S, practice_s=10.0, rating_s=4.0,
                                             abandon_s=ABANDON_S))
    settings = tmp_path / 'drive.yaml'
    settings.write_text(SETTINGS.format(drive_s=DRIVE_S, practice_s=10.0, rating_s=4.0,
                                        abandon_s=ABANDON_S))
    study = tmp_path / 'study'
    drive = Drive(study, 'P02', long_settings)
    who = Participant()
    try:
        page = browser.new_page(viewport=VIEWPORT)
        page.goto(drive.url)
        # drive 1: the tab is closed 2 s in
        drive_once(page, who, stop_after_s=2.0)
        page.close()
        drive.wait_for(r'stops here')
        drive.finish()
    finally:
        drive.kill()
    (record,) = json.loads((study / 'P02' / 'session.json').read_text())['drives']
    assert record['status'] == 'abandoned'
    closed = study / record['bag']
    assert check_bag_directory(closed) == []         # the abandoned drive's bag is finished
    assert custom_data(closed)['trust_av.drive.status'] == 'abandoned'
    phases = _phases(closed)
    # after the tab closed: coast, then brake, never driven again (an input gap under load
    # may coast and hold earlier: the last driven phase is where the tab closed)
    closed_at = max(i for i, phase in enumerate(phases) if phase not in ('coast', 'brake'))
    tail = phases[closed_at + 1:]
    assert tail[:1] == ['coast'] and tail[-1] == 'brake', tail
    assert tail == sorted(tail, key=['coast', 'brake'].index), tail
    you = read_drive(closed).odometry['/human/odom']
    status_times = [m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
                    for m in _messages(closed, '/human/driver_status')]
    brake_from = status_times[closed_at + 1 + tail.index('brake')] - float(
        custom_data(closed)['trust_av.drive.start_ns']) * 1e-9
    braking = you[you[:, 0] > brake_from + 0.3]
    assert len(braking) > 5 and np.all(np.diff(braking[:, 2]) <= 1e-9)   # slowing down
    # the AV was not affected: the planner kept commanding and the AV kept driving to the end
    ego = read_drive(closed).odometry['/ego/odom']
    driven_s = float(custom_data(closed)['trust_av.drive.driven_s'])
    commands = _messages(closed, '/ego/accel_cmd')
    assert ego[-1, 0] > brake_from + 2.0 and len(commands) > 5 * driven_s   # half its rate
    assert (_stamp_ns(commands[-1]) - int(custom_data(closed)['trust_av.drive.start_ns'])) \
        / 1e9 > brake_from + 2.0
    # the same command resumes the session with the abandoned condition; killed during
    # that drive (a crash: nothing finished)
    again = Drive(study, 'P02', long_settings)
    try:
        assert again.wait_for(r'drive 2 \((\w+)\): waiting').group(1) == record['condition']
        page = browser.new_page(viewport=VIEWPORT)
        page.goto(again.url)
        drive_once(page, Participant(), stop_after_s=2.0)
        again.process.send_signal(signal.SIGKILL)
        again.process.wait(timeout=30)
        page.wait_for_function("document.getElementById('status').textContent"
                               ".includes('connection lost')", timeout=10_000)
        page.close()
    finally:
        again.kill()
    session = json.loads((study / 'P02' / 'session.json').read_text())
    assert session['drives'] == [record]                  # the killed drive is not counted
    third = Drive(study, 'P02', settings)
    try:
        assert third.wait_for(r'drive 2 \((\w+)\): waiting').group(1) == record['condition']
        # the killed drive's directory is kept beside the new attempt, not overwritten
        kept = study / 'P02' / f'drive_02_{record["condition"]}.attempt1'
        assert kept.is_dir() and any(kept.glob('*.mcap'))
        page = browser.new_page(viewport=VIEWPORT)
        page.goto(third.url)
        assert drive_once(page, who, answers=ANSWERS) in ('questionnaire', 'ready')
        # the next condition's start screen: a stop signal there ends the command
        assert third.wait_for(r'drive 3 \((\w+)\): waiting').group(1) != record['condition']
    finally:
        third.kill()
    assert third.process.returncode == 128 + signal.SIGTERM
    session = json.loads((study / 'P02' / 'session.json').read_text())
    assert [d['status'] for d in session['drives']] == ['abandoned', 'done']
    assert (study / session['drives'][0]['bag']).is_dir()   # nothing recorded is lost


FOREIGN_PAGE = """<!doctype html><script>
window.result = [];
for (const query of ['?token=' + location.hash.slice(1), '']) {
  const ws = new WebSocket('ws://127.0.0.1:PORT/ws' + query);
  ws.onopen = () => window.result.push('open');
  ws.onclose = () => window.result.push('closed');
}
</script>"""
"""Another web page on this machine that knows the drive's port and even its token."""
ROBUST_DRIVE_S = 45.0
"""The misuse drive's length. Each step waits on the page, but the drive ends on time, and
every step up to the reopened tab's rating must fit in it: 16 s did on an idle host and not
beside the rest of the suite on a host three times slower (the drive ended, and the reopened
tab waited for a drive that was over); at load 14 on that host the steps took 25.5 s."""
ROBUST_RATING_S = 3.0
ROBUST = f"""/**/drive:
  ros__parameters:
    drive_duration_s: {ROBUST_DRIVE_S}
    practice: false
    rating_period_s: {ROBUST_RATING_S}
    abandon_after_s: 8.0
    start_timeout_s: 120.0
    questionnaire_timeout_s: 60.0
    port: 0
    on_collision: continue
    condition_names: [low_alpha]
    condition_alphas: [0.0]
    condition_predictors: [ca]
    condition_traces: [us06]
"""


def _foreign_server(port: int) -> Any:
    from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

    body = FOREIGN_PAGE.replace('PORT', str(port)).encode()

    class Page(BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            self.send_response(200)
            self.send_header('Content-Type', 'text/html')
            self.send_header('Content-Length', str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *_args: Any) -> None:
            pass

    server = ThreadingHTTPServer(('127.0.0.1', 0), Page)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server


def _shown(page: Any, selector: str) -> bool:
    return bool(page.locator(selector).is_visible())


def test_no_participant_second_tab_or_other_page_breaks_a_drive(
        tmp_path: Path, browser: Any) -> None:
    """One drive, every misuse in turn: a foreign page, a second tab, the gas held at the
    start (a collision), stray messages, a flood, a take-over, a closed and reopened tab."""
    settings = tmp_path / 'drive.yaml'
    settings.write_text(ROBUST)
    study = tmp_path / 'study'
    drive = Drive(study, 'P04', settings)
    port = int(drive.url.rsplit(':', 1)[1].strip('/'))
    context = browser.new_context(viewport=VIEWPORT)
    foreign = _foreign_server(port)
    try:
        first = context.new_page()
        first.goto(drive.url)
        first.wait_for_selector('#start', state='visible', timeout=120_000)
        assert first.text_content('#title') == 'Drive 1 of 1'
        assert 'automated vehicle' in first.text_content('#intro')
        # another web page, even one that knows the token, cannot open the WebSocket
        token = first.evaluate('window.drive.token')
        evil = context.new_page()
        evil.goto(f'http://127.0.0.1:{foreign.server_address[1]}/#{token}')
        evil.wait_for_function('window.result.length === 2', timeout=10_000)
        assert evil.evaluate('window.result') == ['closed', 'closed']
        evil.close()
        # a second tab is told another tab drives
        second = context.new_page()
        second.goto(drive.url)
        second.wait_for_selector('#control', state='visible', timeout=10_000)
        assert 'Another tab is driving' in second.text_content('#control')
        # the gas held at the start: the car hits the AV, stops behind it, the page says so
        first.bring_to_front()
        first.keyboard.down('ArrowUp')
        first.click('#start')
        first.wait_for_selector('#crash', state='visible', timeout=30_000)
        assert 'hit the AV' in first.text_content('#crash')
        first.keyboard.up('ArrowUp')
        assert float(first.locator('#gap').get_attribute('data-m')) > -0.1
        # stray messages: a questionnaire and a rating nobody asked for, a start, junk
        first.evaluate("""() => {
            const ws = window.drive.ws;
            ws.send(JSON.stringify({type: 'questionnaire', answers: Array(12).fill(7)}));
            ws.send(JSON.stringify({type: 'rating', id: 999, value: 100}));
            ws.send(JSON.stringify({type: 'ready'}));
            ws.send(JSON.stringify({type: 'ack', seq: 123456}));
            ws.send('not json');
        }""")
        # a flood of 10,000 messages from the driving tab: refused, the connection closed
        # after 200 of them (the tab reconnects by itself); the other tab's frames go on
        flood_start = second.evaluate('performance.now()')
        first.evaluate("""() => {
            const ws = window.flooded = window.drive.ws;
            for (let k = 0; k < 10000; k++) {
                ws.send(JSON.stringify(k % 2 ? {type: 'input', seq: k, accel_mps2: 1e308}
                                            : {type: 'ack', seq: k}));
            }
        }""")
        second.wait_for_function(
            f'window.drive.frameTimes.filter(t => t > {flood_start}).length > 20',
            timeout=30_000)
        frames = second.evaluate(f'window.drive.frameTimes.filter(t => t > {flood_start})')
        print(f'flood: the other tab got {len(frames)} frames in '
              f'{(frames[-1] - flood_start) / 1000:.1f} s, largest gap '
              f'{max(np.diff(frames)):.0f} ms')
        # the flooding tab drives again on a new connection (an answer given before would
        # go nowhere); a rating prompt is answered in it
        first.wait_for_function('window.drive.ws !== window.flooded && window.drive.ws'
                                '.readyState === 1 && window.drive.controlling', timeout=30_000)
        first.wait_for_selector('#rating', state='visible', timeout=15_000)
        first.locator('#rating-slider').fill('60')
        first.click('#rating-submit')
        # the second tab takes over explicitly; the first is told
        second.bring_to_front()
        second.click('#take-over')
        first.wait_for_selector('#control', state='visible', timeout=10_000)
        second.wait_for_selector('#control', state='hidden', timeout=10_000)
        first.evaluate("window.drive.ws.send(JSON.stringify({type: 'input', seq: 1, "
                       "accel_mps2: 2}))")
        first.close()
        # the driving tab is closed and reopened: the true time left, the same schedule
        second.wait_for_function("document.getElementById('time-left').dataset.s",
                                 timeout=10_000)
        asked = time.monotonic()
        left_before = float(second.locator('#time-left').get_attribute('data-s'))
        read_before = (asked, time.monotonic())
        prompt_before = second.evaluate('window.drive.prompt')
        second.close()
        reopened = context.new_page()
        reopened.goto(drive.url)
        reopened.wait_for_function("window.drive.controlling && document.getElementById("
                                   "'time-left').dataset.s", timeout=30_000)
        asked = time.monotonic()
        left_after = float(reopened.locator('#time-left').get_attribute('data-s'))
        read_after = (asked, time.monotonic())
        # the time left went down by the time that passed between the two readings (each
        # bracketed by this clock; a page shows a frame up to half a second old)
        passed = (read_after[0] - read_before[1], read_after[1] - read_before[0])
        assert passed[0] - 0.5 < left_before - left_after < passed[1] + 0.5, \
            (left_before, left_after, passed)
        reopened.wait_for_selector('#rating', state='visible', timeout=15_000)
        assert prompt_before is None or reopened.evaluate('window.drive.prompt') >= prompt_before
        reopened.locator('#rating-slider').fill('40')
        reopened.click('#rating-submit')
        box = reopened.locator('#pedal').bounding_box()
        reopened.mouse.move(box['x'] + box['width'] / 2, box['y'] + box['height'] / 2 + 10)
        reopened.mouse.down()                    # a light brake: the participant is there
        print(f'every step done {reopened.locator("#time-left").get_attribute("data-s")} s '
              'before the end of the drive')
        reopened.wait_for_function("window.drive.phase === 'questionnaire'", timeout=60_000)
        reopened.mouse.up()
        assert reopened.evaluate('window.innerHeight') >= reopened.locator(
            '#questionnaire-submit').bounding_box()['y']      # it fits the window
        assert reopened.locator('#questionnaire input:checked').count() == 0   # no default
        for i, value in enumerate(ANSWERS):
            reopened.check(f'input[name="item{i + 1}"][value="{value}"]')
        reopened.click('#questionnaire-submit')
        reopened.wait_for_function("window.drive.phase === 'finished'", timeout=60_000)
        output = drive.finish()
        reopened.wait_for_function('window.drive.ws.readyState === WebSocket.CLOSED',
                                   timeout=10_000)
        assert 'connection lost' not in reopened.text_content('#status')   # final
        assert 'session is complete' in reopened.text_content('#message')
    finally:
        foreign.shutdown()
        context.close()
        drive.kill()
    assert '1 collisions' in output
    session = json.loads((study / 'P04' / 'session.json').read_text())
    (record,) = session['drives']
    assert record['status'] == 'done' and record['summary']['collisions'] >= 1
    bag = study / record['bag']
    assert check_bag_directory(bag) == []
    meta = custom_data(bag)
    assert int(meta['trust_av.drive.collisions']) >= 1
    refused = {k.removeprefix('trust_av.drive.refused.'): int(v) for k, v in meta.items()
               if k.startswith('trust_av.drive.refused.')}
    assert sum(refused.values()) == int(meta['trust_av.drive.refused'])
    for reason in ('questionnaire during driving', 'rating outside a prompt',
                   'ready during driving', 'input over the control rate',
                   'ack of no sent frame', 'not a page message',
                   'a message from a tab that is not driving'):
        assert refused.get(reason_key(reason), 0) >= 1, (reason, refused)
    assert refused[reason_key('more than 200 messages in a second: the connection '
                              'closed')] == 1
    assert sum(v for k, v in refused.items() if 'websocket' in k) >= 2     # the foreign page
    # nothing refused reached the graph: every command within the pedal's range, at most
    # about the control rate, and the recorded answers are the participant's
    commands = [m.accel.linear.x for m in _messages(bag, '/human/accel_cmd')]
    assert all(-6.0 <= a <= 2.5 for a in commands)
    assert len(commands) < ROBUST_DRIVE_S * 10 * 1.5
    data = read_drive(bag)
    assert data.questionnaire[:12] == ANSWERS
    np.testing.assert_allclose(sorted(data.ratings), [0.40, 0.60])
    # the car never went through the AV
    you, av = data.odometry['/human/odom'], data.odometry['/ego/odom']
    # while both are recorded (as the nodes stop, the AV's odometry may end first)
    you = you[you[:, 0] <= av[-1, 0]]
    gaps = np.interp(you[:, 0], av[:, 0], av[:, 1]) - 4.5 - you[:, 1]
    assert gaps.min() > -0.2
    events = [m.status[0].message for m in _messages(bag, '/driver/events')]
    assert events.index('start') < events.index('collision')
    for kind in ('take_over', 'page_lost', 'rating_prompt', 'end'):
        assert kind in events
    lost = events.index('page_lost')
    assert 'page_connected' in events[lost:]          # the interruption and the return
    # the rating schedule went on through the interruptions: every prompt was due on the
    # grid and sent when due or later (a tick late under load sends it late: CI's host sent
    # the prompt due at 3 s at 4.26 s), never earlier
    start_ns = int(meta['trust_av.drive.start_ns'])
    prompts = [((_stamp_ns(m) - start_ns) / 1e9,
                float(next(v.value for v in m.status[0].values if v.key == 'due_s')))
               for m in _messages(bag, '/driver/events') if m.status[0].message == 'rating_prompt']
    assert len(prompts) >= 3
    grid = ROBUST_RATING_S
    assert all(abs(due / grid - round(due / grid)) < 1e-3 and round(due / grid) >= 1
               and sent >= due - 1e-3 for sent, due in prompts), prompts
    # every registered trust model's trust, live during the drive
    trust = _messages(bag, '/driver/model_trust')   # a plan pair every 0.1 s: half of them
    assert len(trust) > 5 * float(meta['trust_av.drive.driven_s'])
    assert list(trust[0].name) == list(names(TRUST_MODELS))
    assert all(np.isfinite(m.position).all() for m in trust)
    assert all(((np.asarray(m.position) >= 0.0) & (np.asarray(m.position) <= 1.0)).all()
               for m in trust)                  # the common scale
