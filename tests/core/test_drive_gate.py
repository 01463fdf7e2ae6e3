"""Who may drive and what a page may send, without a graph or a browser: the message gate
(phase, rate, pedal range, prompts, acknowledgements), the server's origin, token and
one-controlling-tab rules (a plain WebSocket client plays the pages), the follower's
collision check and the planner's observation at a gap at or below zero."""

from __future__ import annotations

import json
import math
import queue
import urllib.error
import urllib.request
from collections.abc import Iterator
from typing import Any

import pytest
from websockets.exceptions import ConnectionClosed, InvalidStatus
from websockets.sync.client import connect

from human_driver_sim.follower_plant import COLLISION_CLEAR_M, AvTrack, contact
from trust_av.drive.gate import (
    DRIVING,
    INPUT_BURST,
    QUESTIONNAIRE,
    READY,
    TRUST_BURST,
    TRUST_PER_S,
    WAIT,
    Gate,
)
from trust_av.drive.link import DriveLink
from trust_av.drive.server import FLOOD_MESSAGES_PER_S, DriveServer
from trust_av_common.kinematics import VehicleState
from trust_av_planner.planner import observe

MS = 1_000_000


def _gate(phase: str = DRIVING) -> Gate:
    gate = Gate(10.0, -6.0, 2.5)
    gate.set_phase(READY)
    gate.set_phase(phase)
    return gate


def test_messages_that_do_not_fit_the_phase_are_refused_and_counted() -> None:
    gate = _gate(DRIVING)
    assert gate.admit({'type': 'input'}) and gate.admit({'type': 'rating'})
    assert not gate.admit({'type': 'questionnaire', 'answers': [1] * 12})
    assert not gate.admit({'type': 'ready'})
    gate.set_phase(QUESTIONNAIRE)
    assert gate.admit({'type': 'questionnaire'}) and not gate.admit({'type': 'input'})
    assert gate.take_questionnaire() and not gate.take_questionnaire()   # one per drive
    assert gate.refused_counts() == {'questionnaire during driving': 1,
                                     'ready during driving': 1,
                                     'input during questionnaire': 1,
                                     'a second questionnaire': 1}


def test_pedal_samples_are_clipped_and_rate_limited() -> None:
    gate = _gate()
    high = gate.sample({'accel_mps2': 1e308}, 0)
    low = gate.sample({'accel_mps2': -1e308}, 0)
    assert high is not None and (high.accel_mps2, high.clipped) == (2.5, True)
    assert low is not None and (low.accel_mps2, low.clipped) == (-6.0, True)
    for bad in (math.nan, math.inf, '1', True, None):
        assert gate.sample({'accel_mps2': bad}, 0) is None
    # a burst above the control rate passes INPUT_BURST samples, then one per period
    flood = [gate.sample({'accel_mps2': 1.0}, 1000 * MS + k) for k in range(10_000)]
    assert sum(s is not None for s in flood) == INPUT_BURST
    later = [gate.sample({'accel_mps2': 1.0}, (1000 + 101 * k) * MS) for k in range(1, 11)]
    assert all(s is not None for s in later)
    seqs = [s.seq for s in [high, low, *flood, *later] if s is not None]
    assert seqs == list(range(1, len(seqs) + 1))
    assert gate.refused_counts()['input over the control rate'] == 10_000 - INPUT_BURST


def _stalled(sent_ms: list[float], stall_from_ms: float, stall_ms: float) -> list[int]:
    """Arrival times (ns) of samples sent at ``sent_ms``: 2 ms on the way, except that
    nothing is read while this process stalls (those arrive together at its end)."""
    out = []
    for t in sent_ms:
        arrived = t + 2.0
        if stall_from_ms <= arrived < stall_from_ms + stall_ms:
            arrived = stall_from_ms + stall_ms
        out.append(round(arrived * MS))
    return out


def test_samples_bunched_by_a_stall_of_the_server_pass_on_the_page_s_clock() -> None:
    # a page sending at the control rate (10 Hz), this process stalled for 2.6 s: 26
    # samples arrive at once; counted on the page's clock, none is over the rate
    sent = [5000.0 + 100.0 * k for k in range(60)]
    arrived = _stalled(sent, 6000.0, 2600.0)
    gate = _gate()
    taken = [gate.sample({'accel_mps2': 1.0, 't_ms': t}, ns)
             for t, ns in zip(sent, arrived, strict=True)]
    assert all(s is not None for s in taken) and gate.refused_counts() == {}
    # the same samples without their send time count at their arrival: the stall's
    # bunch is over the rate (the rule before pages stamped their samples)
    unstamped = _gate()
    for ns in arrived:
        unstamped.sample({'accel_mps2': 1.0}, ns)
    assert unstamped.refused_counts()['input over the control rate'] >= 26 - INPUT_BURST


def test_a_page_s_clock_counts_only_as_far_as_it_keeps_to_the_server_s() -> None:
    gate = _gate()
    # t_ms, when sent, is a finite number (a JSON null, a string, a bool is not)
    for bad in (math.nan, math.inf, -math.inf, '5', True, None, [1]):
        assert gate.sample({'accel_mps2': 1.0, 't_ms': bad}, 0) is None
    assert gate.refused_counts() == {'input with a t_ms that is not a finite number': 7}
    # send times running back and forth by 100 ms (one sample's worth), all arriving at
    # once, refill nothing: the page's clock never runs ahead of the arrivals
    taken = [gate.sample({'accel_mps2': 1.0, 't_ms': 100.0 * (k % 2)}, MS)
             for k in range(100)]
    assert sum(s is not None for s in taken) == INPUT_BURST
    # a page stamped ahead of its arrivals counts at its arrival: a sample at 0, then one
    # stamped 3.5 s later that arrives 100 ms later is 0.9 s early for a refill
    late = _gate()
    assert all(late.sample({'accel_mps2': 1.0, 't_ms': 0.0}, 0) is not None
               for _ in range(INPUT_BURST))                  # the burst used up
    assert late.sample({'accel_mps2': 1.0, 't_ms': 3500.0}, 100 * MS) is not None
    assert late.sample({'accel_mps2': 1.0, 't_ms': 7000.0}, 150 * MS) is None
    assert late.refused_counts() == {'input over the control rate': 1}


def test_a_stall_at_the_start_of_a_connection_is_absorbed_by_the_burst() -> None:
    # before any sample came promptly the page's clock is not known: a bunch at the very
    # start counts at its arrival, and the burst takes up to INPUT_BURST of it
    sent = [100.0 * k for k in range(INPUT_BURST + 3)]
    gate = _gate()
    taken = [gate.sample({'accel_mps2': 1.0, 't_ms': t}, 2000 * MS) for t in sent]
    assert sum(s is not None for s in taken) == INPUT_BURST
    # once one sample came promptly, later bunches pass
    assert gate.sample({'accel_mps2': 1.0, 't_ms': 3000.0}, 3001 * MS) is not None
    bunch = [gate.sample({'accel_mps2': 1.0, 't_ms': 3100.0 + 100 * k}, 6000 * MS)
             for k in range(25)]
    assert all(s is not None for s in bunch)


@pytest.mark.parametrize('reconnect_every', [0, 1, 10])
def test_a_page_whose_clock_runs_fast_is_held_to_the_control_rate(
        reconnect_every: int) -> None:
    """A hostile page: a sample every 10 ms of the server's time stamped 1 s apart (its
    clock 100 times fast), for 60 s, never reconnecting, or reconnecting every sample or
    every 10 (each connection's clock is put on the server's anew). Its clock never runs
    ahead of its arrivals, so what passes is the control rate over the drive plus the
    burst, nothing more."""
    link = DriveLink(_gate())
    gate = link.gate
    taken = 0
    duration_s = 60.0
    for k in range(int(duration_s * 100)):
        if reconnect_every and k % reconnect_every == 0:
            link.on_event('page_connected', k * 10 * MS)
        taken += gate.sample({'accel_mps2': 1.0, 't_ms': 1000.0 * k}, k * 10 * MS) is not None
    assert taken <= INPUT_BURST + gate.rate_hz * duration_s
    assert gate.refused_counts() == {'input over the control rate': duration_s * 100 - taken}


def test_a_new_page_brings_its_own_clock() -> None:
    link = DriveLink(_gate())
    for k in range(20):                           # a tab open for 100 s, at 10 Hz
        assert link.gate.sample({'accel_mps2': 0.0, 't_ms': 100_000.0 + 100 * k},
                                k * 100 * MS) is not None
    link.on_event('page_lost', 2000 * MS)
    link.on_event('page_connected', 2500 * MS)   # a new tab: its clock starts near 0
    for k in range(20):
        assert link.gate.sample({'accel_mps2': 0.0, 't_ms': 300.0 + 100 * k},
                                (3000 + k * 100) * MS) is not None
    link.on_event('take_over', 5000 * MS)         # another tab, open for 1000 s
    assert link.gate.sample({'accel_mps2': 0.0, 't_ms': 1e6}, 5100 * MS) is not None
    assert link.gate.refused_counts() == {}


def test_ratings_only_answer_open_prompts() -> None:
    gate = _gate()
    assert gate.rating({'type': 'rating', 'id': 1, 'value': 50}, 0) is None   # none open
    prompt = gate.open_prompt(1000 * MS)
    assert gate.open_prompts() == [prompt]
    assert gate.rating({'id': prompt, 'value': 101}, 0) is None
    assert gate.rating({'id': prompt, 'value': 40}, 3500 * MS) == (prompt, 40.0, 2.5)
    assert gate.rating({'id': prompt, 'value': 40}, 3600 * MS) is None       # answered
    assert gate.open_prompts() == []
    gate.set_phase(WAIT)                  # a prompt open as the drive ends may be answered
    late = gate.open_prompt(0)
    assert gate.rating({'id': late, 'value': 10}, MS) is not None
    assert gate.refused_counts() == {'rating outside a prompt': 2, 'rating not in [0, 100]': 1}


@pytest.mark.parametrize('value', [-0.5, 100.5, math.nan, math.inf, '50', True, None, 10**400])
def test_the_continuous_scale_keeps_only_values_on_it(value: Any) -> None:
    gate = Gate(10.0, -6.0, 2.5, continuous=True)
    gate.set_phase(READY)
    assert gate.admit({'type': 'trust'})          # set on the start screen
    assert gate.trust({'value': 30}, 5 * MS) == 30.0
    assert gate.trust({'value': value}, 6 * MS) is None
    assert gate.trust_now() == (30.0, 5 * MS)      # the refused value left it where it was
    assert gate.refused_counts() == {'rating not in [0, 100]': 1}


def test_the_continuous_scale_is_per_drive_rate_limited_and_only_in_its_study() -> None:
    prompted = _gate()
    assert prompted.trust({'value': 50}, 0) is None and prompted.trust_now() is None
    assert prompted.refused_counts() == {'trust without the continuous rating': 1}
    gate = Gate(10.0, -6.0, 2.5, continuous=True)
    gate.set_phase(READY)
    gate.set_phase(DRIVING)
    # a burst is taken, then one a tenth of a second (TRUST_PER_S) on the arrival clock
    taken = [gate.trust({'value': k}, 1000 * MS) for k in range(TRUST_BURST + 3)]
    assert taken[:TRUST_BURST] == [float(k) for k in range(TRUST_BURST)]
    assert taken[TRUST_BURST:] == [None] * 3
    assert gate.trust_now() == (TRUST_BURST - 1.0, 1000 * MS)
    assert gate.trust({'value': 77}, 1000 * MS + int(1e9 / TRUST_PER_S)) == 77.0
    assert gate.refused_counts() == {'trust over its rate': 3}
    gate.set_phase(WAIT)
    assert not gate.admit({'type': 'trust'})       # the drive is over
    gate.set_phase(READY)                          # the next drive's scale starts unset
    assert gate.trust_now() is None


def test_latency_comes_only_from_acknowledgements_the_server_sent() -> None:
    gate = _gate()
    gate.sent_ack(7, arrived_ns=0, applied_ns=5 * MS, sent_ns=6 * MS)
    assert gate.echo({'seq': 8}, 10 * MS) is None                     # never sent: forged
    assert gate.echo({'seq': 7}, 20 * MS) == pytest.approx((0.020, 0.005, 0.015))
    assert gate.echo({'seq': 7}, 21 * MS) is None                     # echoed twice
    assert gate.refused_counts() == {'ack of no sent frame': 2}


def test_the_follower_stops_behind_the_av_and_never_drives_through() -> None:
    free = contact(10.0, 5.0, 12.0, 3.0, False)
    assert (free.position_m, free.speed_mps, free.touching, free.new_collision) == \
        (10.0, 5.0, False, False)
    hit = contact(13.0, 5.0, 12.0, 3.0, False)               # overlapping: a collision
    assert (hit.position_m, hit.speed_mps, hit.touching, hit.new_collision) == \
        (12.0, 0.0, True, True)
    pushed = contact(12.4, 4.0, 12.2, 3.0, True)              # pedal on: at the bumper
    assert (pushed.position_m, pushed.speed_mps, pushed.new_collision) == (12.2, 3.0, False)
    near = contact(12.0, 1.0, 12.2, 3.0, True)                # not yet clear: same contact
    assert near.touching and contact(12.3, 1.0, 12.2, 3.0, near.touching).new_collision is False
    clear = contact(10.0, 1.0, 10.0 + COLLISION_CLEAR_M + 0.1, 3.0, True)
    assert not clear.touching
    assert contact(11.0, 1.0, 10.6, 3.0, clear.touching).new_collision


def test_the_av_is_placed_where_its_braking_has_brought_it() -> None:
    """The AV's rear bumper from odometry that is a second old (a stalled host): at its speed
    and its acceleration between its last two messages, x + v·t + a·t²/2, stopping at 0 m/s;
    a constant-speed guess would put it a·t²/2 = 2.5 m further on."""
    s, length = 1_000_000_000, 4.5
    track = AvTrack.first(100.0, 10.5, 0, 0)
    assert track.accel_mps2 == 0.0
    track = track.update(101.0, 10.0, s // 10, 7 * s)        # -0.5 m/s in 0.1 s: -5 m/s^2
    assert track.accel_mps2 == pytest.approx(-5.0)
    assert track.rear_m(7 * s, length) == pytest.approx(101.0 - length)
    assert track.rear_m(8 * s, length) == pytest.approx(101.0 + 10.0 - 2.5 - length)
    assert track.update(99.0, 11.0, s // 20, 8 * s) is track  # an older message: not newer
    slow = AvTrack.first(50.0, 2.5, 0, 0).update(50.2, 2.0, s // 10, 0)
    stopped = 50.2 + 2.0 * 0.4 - 0.5 * 5.0 * 0.4 ** 2 - length    # at rest after 0.4 s
    assert slow.rear_m(s, length) == pytest.approx(stopped)
    assert slow.rear_m(60 * s, length) == pytest.approx(stopped)  # and never backwards
    assert AvTrack.first(0.0, 0.0, 0, 5 * s).rear_m(0, length) == -length   # a clock behind


@pytest.mark.parametrize(('gap', 'speed'), [(-51.0, 0.0), (0.0, 0.0), (-1.0, 3.0)])
def test_planner_observes_a_crash_without_dividing(gap: float, speed: float) -> None:
    seen = observe(VehicleState(100.0, 0.0), VehicleState(100.0 - 4.5 - gap, speed), 0.0, 4.5,
                   10.0)
    assert seen.gap_m == pytest.approx(gap) and seen.time_headway_s == 0.0


# ---- the server ----------------------------------------------------------------------------
@pytest.fixture
def served() -> Iterator[tuple[DriveServer, queue.Queue[Any]]]:
    inbox: queue.Queue[Any] = queue.Queue()
    server = DriveServer(lambda m, _ns: inbox.put(('message', m)), lambda: {'type': 'hello'},
                         on_event=lambda kind, _ns: inbox.put(('event', kind)),
                         on_refused=lambda reason: inbox.put(('refused', reason)), port=0)
    server.start()
    try:
        yield server, inbox
    finally:
        server.stop()


def _open(server: DriveServer, *, origin: str | None = None, token: str | None = None,
          host: str | None = None) -> Any:
    origin = origin if origin is not None else f'http://127.0.0.1:{server.port}'
    token = token if token is not None else server.token
    headers = {'Origin': origin, **({'Host': host} if host else {})}
    return connect(f'ws://127.0.0.1:{server.port}/ws?token={token}',
                   additional_headers=headers, open_timeout=10)


def _received(ws: Any, kind: str) -> dict[str, Any]:
    while True:
        message: dict[str, Any] = json.loads(ws.recv(timeout=10))
        if message['type'] == kind:
            return message


def _drain(inbox: queue.Queue[Any], wait_s: float = 0.5) -> list[Any]:
    out = []
    try:
        while True:
            out.append(inbox.get(timeout=wait_s))
    except queue.Empty:
        return out


def test_only_the_served_page_may_open_the_websocket(
        served: tuple[DriveServer, queue.Queue[Any]]) -> None:
    server, inbox = served
    for kwargs in ({'origin': 'http://evil.example'}, {'origin': 'null'},
                   {'origin': f'http://127.0.0.1:{server.port + 1}'},
                   {'token': 'guess'}, {'token': ''}):
        with pytest.raises(InvalidStatus, match='403'):
            _open(server, **kwargs)
    refused = [r for kind, r in _drain(inbox) if kind == 'refused']
    assert len(refused) == 5 and "origin 'http://evil.example'" in refused[0]
    # the token is in the served page, and only there; a page for another host name (DNS
    # rebinding) is not served
    page = urllib.request.urlopen(server.url, timeout=10).read().decode()
    assert server.token in page
    request = urllib.request.Request(server.url, headers={'Host': f'evil.example:{server.port}'})
    with pytest.raises(urllib.error.HTTPError, match='403'):
        urllib.request.urlopen(request, timeout=10)
    with _open(server, origin=f'http://localhost:{server.port}') as ws:   # the page's origin
        assert _received(ws, 'control')['controlling'] is True


def test_one_tab_drives_a_second_is_told_and_may_take_over(
        served: tuple[DriveServer, queue.Queue[Any]]) -> None:
    server, inbox = served
    with _open(server) as first, _open(server) as second:
        assert _received(first, 'hello') and _received(first, 'control')['controlling']
        told = _received(second, 'control')
        assert (told['controlling'], told['other']) == (False, True)
        second.send(json.dumps({'type': 'input', 'seq': 1, 'accel_mps2': 1.0}))
        first.send(json.dumps({'type': 'input', 'seq': 1, 'accel_mps2': -1.0}))
        seen = _drain(inbox)
        assert ('refused', 'a message from a tab that is not driving') in seen
        assert [m['accel_mps2'] for kind, m in seen if kind == 'message'] == [-1.0]
        second.send(json.dumps({'type': 'take_over'}))
        assert _received(second, 'control')['controlling'] is True
        assert _received(first, 'control') == {'type': 'control', 'controlling': False,
                                               'other': True, 'taken_over': True}
        assert ('event', 'take_over') in _drain(inbox)
        with _open(server) as third:        # a reconnection before the old one is gone
            assert _received(third, 'control')['other'] is True
            second.close()                  # the driving tab closes: the control is free
            assert _received(third, 'control') == {'type': 'control', 'controlling': False,
                                                   'other': False}
            third.send(json.dumps({'type': 'take_over'}))   # what the page that drove does
            assert _received(third, 'control')['controlling'] is True
            events = [e for kind, e in _drain(inbox) if kind == 'event']
            assert events == ['page_lost', 'page_connected']
    events = [e for kind, e in _drain(inbox) if kind == 'event']
    assert events == ['page_lost']          # the driving tab closed: an interruption


def test_a_flooding_connection_is_closed_and_the_others_go_on(
        served: tuple[DriveServer, queue.Queue[Any]]) -> None:
    server, inbox = served
    with _open(server) as flooder, _open(server) as other:
        _received(other, 'control')
        with pytest.raises(ConnectionClosed) as closed:
            for k in range(10_000):
                flooder.send(json.dumps({'type': 'input', 'seq': k, 'accel_mps2': 1.0}))
            flooder.recv(timeout=10)
        assert closed.value.rcvd is None           # dropped, no closing handshake
        server.send({'type': 'state'})
        assert _received(other, 'state') == {'type': 'state'}
    seen = _drain(inbox)
    # at least one second's worth passed (more only if the host is too slow to take 200
    # messages within a second), then nothing more
    assert FLOOD_MESSAGES_PER_S <= len([m for kind, m in seen if kind == 'message']) < 10_000
    assert ('refused', f'more than {FLOOD_MESSAGES_PER_S} messages in a second: the '
            'connection closed') in seen
