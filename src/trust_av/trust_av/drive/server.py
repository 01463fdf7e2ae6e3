"""The drive's web server: the page (HTML, JS and the vendored Konva it draws with, shipped
in ``drive/web``) and one WebSocket (``/ws``) that carries pedal samples, ratings and the
questionnaire in, and the vehicles' state out. Runs its own asyncio loop in a thread;
localhost only by default.

Only the served page drives: the page and the WebSocket answer only requests whose ``Host``
is the server's own address, the WebSocket handshake needs the page's own ``Origin`` and the
per-server token written into the served page (``?token=``); anything else is refused
(403) and counted. One connection controls the car at a time: the first one; a later tab is
told another tab is driving (``control``, ``controlling: false``) and its messages are
refused and counted, until it sends ``take_over`` (recorded as an event); a controlling tab
that closes frees the control: the next tab that connects drives, and the tabs still open
are told (the page that drove before takes it back by itself: a reconnection that came
before the old connection was gone). A connection
that floods (more than ``FLOOD_MESSAGES_PER_S`` messages in a second) is closed; messages
are handled one at a time, every other connection's traffic going first between two.

Messages are JSON objects with a ``type`` (the page's protocol, not ROS: the drive turns
each into standard ROS messages). In: ``ready``, ``input`` (``seq``, ``accel_mps2``,
``t_ms``: the page's send time, for the rate limit only),
``ack`` (``seq``: a state frame's acknowledgement echoed), ``rating`` (``id`` of the prompt,
``value`` 0-100), ``trust`` (``value`` 0-100: the continuous scale's new position, when the
study rates continuously), ``questionnaire`` (``answers``: 12 integers 1-7), ``take_over``. Out:
``hello``, ``control``, ``phase``, ``state``, ``rate`` (a rating prompt).
"""

from __future__ import annotations

import asyncio
import hmac
import json
import logging
import secrets
import threading
import time
from collections.abc import Callable
from http import HTTPStatus
from importlib import resources
from typing import Any

from websockets.asyncio.server import Server, ServerConnection, serve
from websockets.datastructures import Headers
from websockets.exceptions import ConnectionClosed
from websockets.http11 import Request, Response

from trust_av.errors import TrustAvAppError

__all__ = ['FLOOD_MESSAGES_PER_S', 'DriveServer', 'parse_message']

LOG = logging.getLogger(__name__)
PAGES = {'/': ('index.html', 'text/html; charset=utf-8'),
         '/drive.js': ('drive.js', 'text/javascript; charset=utf-8'),
         '/drive.css': ('drive.css', 'text/css; charset=utf-8'),
         '/view.js': ('view.js', 'text/javascript; charset=utf-8'),
         '/vendor/konva/konva.min.js': ('vendor/konva/konva.min.js',
                                        'text/javascript; charset=utf-8')}
"""Path -> (file in ``trust_av/drive/web``, content type): the page, its script and style
and the library it draws with (vendored: ``web/vendor/README.md``)."""
CONTENT_SECURITY_POLICY = ("default-src 'none'; script-src 'self' 'unsafe-eval'; "
                           "style-src 'self'; img-src 'self'; connect-src 'self'; "
                           "base-uri 'none'; form-action 'none'; frame-ancestors 'none'")
"""Sent with every file: the page runs scripts, styles and images only from its own origin
(no inline script) and connects only to it (its WebSocket: ``'self'`` covers ``ws:`` on the
same host and port), so nothing is fetched from elsewhere even by mistake. The page
evaluates no string; ``'unsafe-eval'`` is there for the browser tests and the synthetic
participant, whose Playwright ``wait_for_function`` evaluates its predicate in the page."""
MESSAGE_TYPES = frozenset({'ready', 'input', 'ack', 'rating', 'trust', 'questionnaire',
                           'take_over'})
MAX_MESSAGE_BYTES = 4096
TOKEN_MARK = b'__DRIVE_TOKEN__'
"""Replaced in the served ``index.html`` by the server's token."""
LOOPBACK = ('127.0.0.1', 'localhost')
FLOOD_MESSAGES_PER_S = 200
"""A connection that sends more messages than this within one second is dropped (its TCP
connection aborted; the page reconnects by itself): a page sends about 2 x
``control_rate_hz`` a second."""
MAX_CONNECTIONS = 8
"""WebSocket connections served at once; a handshake beyond is refused (403) and counted
(every connection gets every state frame: a script opening thousands would slow the
driving tab's)."""


class ServerError(TrustAvAppError):
    """The server cannot start (e.g. the port is taken); the message says why."""


def page_file(name: str) -> bytes:
    """One of the page's files, as shipped in the package."""
    return resources.files('trust_av.drive').joinpath('web', *name.split('/')).read_bytes()


def parse_message(text: str | bytes) -> dict[str, Any]:
    """One message from the page.

    Raises:
        ValueError: not a JSON object with a known ``type`` (named), nested too deep for
            the parser included.
    """
    try:
        data = json.loads(text)
    except RecursionError as err:          # "[[[[...": 4 KB nest deeper than the stack
        raise ValueError(f'not a page message (nested too deep): {str(text)[:80]!r}') \
            from err
    if not isinstance(data, dict) or data.get('type') not in MESSAGE_TYPES:
        raise ValueError(f'not a page message: {str(text)[:80]!r}')
    return data


def one_header(headers: Headers, name: str) -> str | None:
    """The value of a header given once, else None (absent, or given twice: a request with
    two ``Host`` or ``Origin`` headers is refused like one with a wrong one)."""
    values = headers.get_all(name)
    return values[0] if len(values) == 1 else None


class DriveServer:
    """The page and its WebSocket, served from a background thread.

    Args:
        on_message: called in the server's thread with each message of the controlling
            page and the wall time it arrived (ns); it must return quickly.
        on_connect: called in the server's thread when a page connects; returns the
            greeting sent to that page (``hello``).
        on_event: called in the server's thread with an event (``page_connected``,
            ``page_lost``, ``take_over``) of the controlling page and its wall time (ns).
        on_refused: called with the reason of every refused connection or message.
        host: address to listen on.
        port: TCP port (0: any free port).
    """

    def __init__(self, on_message: Callable[[dict[str, Any], int], None],
                 on_connect: Callable[[], dict[str, Any]], *,
                 on_event: Callable[[str, int], None] | None = None,
                 on_refused: Callable[[str], None] | None = None,
                 host: str = '127.0.0.1', port: int = 0) -> None:
        self.on_message = on_message
        self.on_connect = on_connect
        self.on_event = on_event or (lambda _kind, _ns: None)
        self.on_refused = on_refused or (lambda _reason: None)
        self.host, self.port = host, port
        self.token = secrets.token_urlsafe(24)
        self.clients: set[ServerConnection] = set()
        self.controller: ServerConnection | None = None
        self.disconnects = 0
        self._loop: asyncio.AbstractEventLoop | None = None
        self._server: Server | None = None
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None
        self._tasks: set[asyncio.Future[None]] = set()

    @property
    def url(self) -> str:
        """The page's address."""
        return f'http://{self.host}:{self.port}/'

    def start(self) -> str:
        """Start serving; returns the URL.

        Raises:
            ServerError: the address cannot be bound.
        """
        ready = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(ready,), name='drive-server',
                                        daemon=True)
        self._thread.start()
        ready.wait()
        if self._error is not None:
            raise ServerError(f'cannot serve on {self.host}:{self.port}: {self._error}') \
                from self._error
        return self.url

    def _run(self, ready: threading.Event) -> None:
        loop = asyncio.new_event_loop()
        self._loop = loop

        async def open_server() -> Server:
            return await serve(self._handler, self.host, self.port,
                               process_request=self._http, max_size=MAX_MESSAGE_BYTES,
                               compression=None)
        try:
            self._server = loop.run_until_complete(open_server())
            self.port = int(self._server.sockets[0].getsockname()[1])
        except BaseException as err:  # re-raised by start() in the caller's thread
            self._error = err
            ready.set()
            loop.close()
            return
        ready.set()
        loop.run_forever()
        loop.close()

    def hosts(self) -> set[str]:
        """The ``Host`` values of this server's own address."""
        names = {self.host, *LOOPBACK} if self.host in LOOPBACK else {self.host}
        return {f'{name}:{self.port}' for name in names}

    def _refuse(self, reason: str) -> Response:
        LOG.warning('refused: %s', reason)
        self.on_refused(reason)
        return Response(HTTPStatus.FORBIDDEN, 'Forbidden',
                        Headers([('Content-Type', 'text/plain')]), b'forbidden\n')

    def _http(self, _connection: ServerConnection, request: Request) -> Response | None:
        path, _, query = request.path.partition('?')
        host = one_header(request.headers, 'Host')
        if host not in self.hosts():
            return self._refuse(f'a request for host {host!r}')
        if path == '/ws':
            origin = one_header(request.headers, 'Origin')
            if origin not in {f'http://{host}' for host in self.hosts()}:
                return self._refuse(f'a WebSocket from origin {origin!r}')
            token = next((v for k, _, v in (p.partition('=') for p in query.split('&'))
                          if k == 'token'), '')
            if not hmac.compare_digest(token.encode(), self.token.encode()):
                return self._refuse("a WebSocket without the page's token")
            if len(self.clients) >= MAX_CONNECTIONS:
                return self._refuse(f'more than {MAX_CONNECTIONS} WebSocket connections')
            return None                           # the WebSocket handshake goes on
        if path == '/favicon.ico':
            return Response(HTTPStatus.NO_CONTENT, 'No Content', Headers(), b'')
        if path not in PAGES:
            return Response(HTTPStatus.NOT_FOUND, 'Not Found',
                            Headers([('Content-Type', 'text/plain')]), b'not found\n')
        name, kind = PAGES[path]
        body = page_file(name).replace(TOKEN_MARK, self.token.encode())
        return Response(HTTPStatus.OK, 'OK', Headers([
            ('Content-Type', kind), ('Content-Length', str(len(body))),
            ('Content-Security-Policy', CONTENT_SECURITY_POLICY),
            ('X-Content-Type-Options', 'nosniff'), ('Cache-Control', 'no-store')]), body)

    async def _handler(self, connection: ServerConnection) -> None:
        self.clients.add(connection)
        if self.controller is None:
            self.controller = connection
            self.on_event('page_connected', time.time_ns())
        await self._send_one(connection, json.dumps(self.on_connect()))
        await self._send_control(connection)
        window_ns, in_window = 0, 0
        try:
            async for text in connection:
                arrived = time.time_ns()
                if arrived - window_ns > 1_000_000_000:
                    window_ns, in_window = arrived, 0
                in_window += 1
                if in_window > FLOOD_MESSAGES_PER_S:
                    self.on_refused(f'more than {FLOOD_MESSAGES_PER_S} messages in a second: '
                                    'the connection closed')
                    self.clients.discard(connection)
                    await self._release(connection)
                    # dropped at once: a closing handshake would first read (and parse)
                    # everything the flood has queued
                    connection.transport.abort()
                    break
                try:
                    message = parse_message(text)
                except ValueError as err:
                    self.on_refused('not a page message')
                    LOG.debug('refused a message from the page: %s', err)
                else:
                    if message['type'] == 'take_over':
                        await self._take_over(connection, arrived)
                    elif connection is self.controller:
                        self.on_message(message, arrived)
                    else:
                        self.on_refused('a message from a tab that is not driving')
                await asyncio.sleep(0)            # one message at a time: others go first
        except ConnectionClosed:
            pass                                  # a closed tab: counted below
        finally:
            self.clients.discard(connection)
            self.disconnects += 1
            await self._release(connection)

    async def _release(self, connection: ServerConnection) -> None:
        """``connection`` no longer drives (closed, or closing): the control is free; every
        other tab is told (the page that drove before takes it back by itself)."""
        if connection is self.controller:
            self.controller = None
            self.on_event('page_lost', time.time_ns())
            for other in list(self.clients):
                if other is not connection:
                    await self._send_control(other)

    async def _send_control(self, connection: ServerConnection, **extra: bool) -> None:
        await self._send_one(connection, json.dumps({
            'type': 'control', 'controlling': connection is self.controller,
            'other': self.controller is not None and connection is not self.controller,
            **extra}))

    async def _take_over(self, connection: ServerConnection, now_ns: int) -> None:
        if connection is self.controller:
            return
        previous, self.controller = self.controller, connection
        self.on_event('take_over' if previous is not None else 'page_connected', now_ns)
        for client in list(self.clients):
            if client is previous:
                await self._send_control(client, taken_over=True)
            else:
                await self._send_control(client)

    def send(self, message: dict[str, Any]) -> None:
        """Send ``message`` to every connected page (from any thread)."""
        loop = self._loop
        if loop is None or not self.clients:
            return
        text = json.dumps(message, separators=(',', ':'))
        loop.call_soon_threadsafe(self._broadcast, text)

    def _broadcast(self, text: str) -> None:
        for client in list(self.clients):
            task = asyncio.ensure_future(self._send_one(client, text))
            self._tasks.add(task)                # kept until done (the loop holds weak refs)
            task.add_done_callback(self._tasks.discard)

    async def _send_one(self, client: ServerConnection, text: str) -> None:
        try:
            await client.send(text)
        except ConnectionClosed:
            self.clients.discard(client)

    def stop(self) -> None:
        """Stop serving and join the thread."""
        loop, server = self._loop, self._server
        if loop is None or server is None or self._thread is None:
            return

        async def shut() -> None:
            server.close()
            await server.wait_closed()
        # a client that never answers the closing handshake is dropped after close_timeout
        asyncio.run_coroutine_threadsafe(shut(), loop).result(timeout=30)
        loop.call_soon_threadsafe(loop.stop)
        self._thread.join(timeout=10)
