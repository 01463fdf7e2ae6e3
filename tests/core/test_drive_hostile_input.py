"""Hostile traffic a page (or a script with the page's token) can send. Messages that are
valid JSON within 4 KB and still must not raise: integers too large for a float where a
number is expected, and nesting deeper than the parser's stack (the gate refuses and counts
them; the server counts them as not page messages and keeps the connection). Connections
beyond the server's limit: refused and counted until one closes. Requests with a header the
checks read given twice: refused and counted (not a failed handler)."""

from __future__ import annotations

import contextlib
import json
import queue
import socket
import time
from collections.abc import Iterator
from typing import Any

import pytest
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from trust_av.drive.gate import DRIVING, READY, Gate, finite_number
from trust_av.drive.server import (
    MAX_CONNECTIONS,
    MAX_MESSAGE_BYTES,
    DriveServer,
    parse_message,
)

HUGE = 10 ** 400
"""A JSON integer (401 digits) that no float holds."""


def test_a_number_is_a_finite_float_or_nothing() -> None:
    assert finite_number(3) == 3.0 and finite_number(-0.5) == -0.5
    for bad in (HUGE, -HUGE, float('nan'), float('inf'), True, '1', None, [1], {'v': 1}):
        assert finite_number(bad) is None, bad


def test_the_gate_refuses_numbers_no_float_holds() -> None:
    gate = Gate(10.0, -6.0, 2.5)
    gate.set_phase(READY)
    gate.set_phase(DRIVING)
    assert gate.sample({'type': 'input', 'accel_mps2': HUGE}, 0) is None
    prompt = gate.open_prompt(0)
    assert gate.rating({'type': 'rating', 'id': prompt, 'value': HUGE}, 1) is None
    assert gate.rating({'type': 'rating', 'id': HUGE, 'value': 50}, 1) is None
    assert gate.echo({'type': 'ack', 'seq': HUGE}, 1) is None
    assert gate.refused_counts() == {'input without a finite accel_mps2': 1,
                                     'rating not in [0, 100]': 1,
                                     'rating outside a prompt': 1, 'ack of no sent frame': 1}
    # the prompt is still open and takes a real answer
    assert gate.rating({'type': 'rating', 'id': prompt, 'value': 55}, 2)[:2] == (prompt, 55.0)


DEEP = ['[' * (MAX_MESSAGE_BYTES // 2) + ']' * (MAX_MESSAGE_BYTES // 2),
        '{"type": "input", "accel_mps2": ' + '[' * 2000 + ']' * 2000 + '}']


@pytest.mark.parametrize('text', DEEP, ids=['array', 'in_a_message'])
def test_nesting_deeper_than_the_parser_is_not_a_page_message(text: str) -> None:
    assert len(text.encode()) <= MAX_MESSAGE_BYTES
    with pytest.raises(ValueError, match='nested too deep'):
        parse_message(text)


@pytest.fixture
def served() -> Iterator[tuple[DriveServer, queue.Queue[Any]]]:
    inbox: queue.Queue[Any] = queue.Queue()
    gate = Gate(10.0, -6.0, 2.5)
    gate.set_phase(READY)
    gate.set_phase(DRIVING)

    def on_message(message: dict[str, Any], now_ns: int) -> None:
        if gate.admit(message) and message['type'] == 'input':
            inbox.put(('sample', gate.sample(message, now_ns)))

    server = DriveServer(on_message, lambda: {'type': 'hello'},
                         on_refused=lambda reason: inbox.put(('refused', reason)), port=0)
    server.start()
    try:
        yield server, inbox
    finally:
        server.stop()


def test_the_server_keeps_a_connection_that_sends_hostile_json(
        served: tuple[DriveServer, queue.Queue[Any]]) -> None:
    server, inbox = served
    with connect(f'ws://127.0.0.1:{server.port}/ws?token={server.token}',
                 additional_headers={'Origin': f'http://127.0.0.1:{server.port}'},
                 open_timeout=10) as ws:
        for text in DEEP:
            ws.send(text)
        ws.send(json.dumps({'type': 'input', 'seq': 1, 'accel_mps2': HUGE}))
        ws.send(json.dumps({'type': 'input', 'seq': 2, 'accel_mps2': 1.0}))
        seen = []
        while ('sample', None) not in seen or not any(
                kind == 'sample' and s is not None for kind, s in seen):
            seen.append(inbox.get(timeout=10))
        # the connection is still open and still driving: no handler failed
        server.send({'type': 'state'})
        while json.loads(ws.recv(timeout=10))['type'] != 'state':
            pass
    assert [r for kind, r in seen if kind == 'refused'] == ['not a page message'] * 2
    assert [s.accel_mps2 for kind, s in seen if kind == 'sample' and s is not None] == [1.0]


def _open(server: DriveServer) -> Any:
    return connect(f'ws://127.0.0.1:{server.port}/ws?token={server.token}',
                   additional_headers={'Origin': f'http://127.0.0.1:{server.port}'},
                   open_timeout=10)


def test_connections_beyond_the_limit_are_refused_until_one_closes(
        served: tuple[DriveServer, queue.Queue[Any]]) -> None:
    server, inbox = served
    with contextlib.ExitStack() as stack:
        tabs = [stack.enter_context(_open(server)) for _ in range(MAX_CONNECTIONS)]
        for tab in tabs:                      # each is served: greeted and told who drives
            while json.loads(tab.recv(timeout=10))['type'] != 'control':
                pass
        with pytest.raises(InvalidStatus, match='403'):
            _open(server)
        tabs[-1].close()
        deadline = time.monotonic() + 10      # the server notices the close
        while len(server.clients) >= MAX_CONNECTIONS and time.monotonic() < deadline:
            time.sleep(0.02)
        with _open(server) as again:
            assert json.loads(again.recv(timeout=10))['type'] == 'hello'
    refused = []
    while not inbox.empty():
        refused.append(inbox.get())
    assert refused == [('refused', f'more than {MAX_CONNECTIONS} WebSocket connections')]


def _status(server: DriveServer, request: str) -> str:
    with socket.create_connection(('127.0.0.1', server.port), timeout=10) as raw:
        raw.sendall(request.encode())
        return raw.recv(4096).decode(errors='replace').splitlines()[0]


def test_a_header_given_twice_is_refused_and_counted(
        served: tuple[DriveServer, queue.Queue[Any]]) -> None:
    server, inbox = served
    host = f'127.0.0.1:{server.port}'
    upgrade = ('Upgrade: websocket\r\nConnection: Upgrade\r\n'
               'Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n')
    assert _status(server, f'GET / HTTP/1.1\r\nHost: {host}\r\nHost: evil.example\r\n'
                           '\r\n') == 'HTTP/1.1 403 Forbidden'
    assert _status(server, f'GET /ws?token={server.token} HTTP/1.1\r\nHost: {host}\r\n'
                           f'Origin: http://{host}\r\nOrigin: http://evil.example\r\n'
                           f'{upgrade}\r\n') == 'HTTP/1.1 403 Forbidden'
    refused = []
    while not inbox.empty():
        refused.append(inbox.get())
    assert refused == [('refused', 'a request for host None'),
                       ('refused', 'a WebSocket from origin None')]
