"""The drive's web server: the page (plain HTML/JS/canvas shipped in ``drive/web``) and one
WebSocket (``/ws``) that carries pedal samples, ratings and the questionnaire in, and the
vehicles' state out. Runs its own asyncio loop in a thread; localhost only by default.

Messages are JSON objects with a ``type`` (the page's protocol, not ROS: the drive turns
each into standard ROS messages). In: ``ready``, ``input`` (``seq``, ``accel_mps2``,
``page_ms``), ``latency`` (``seq``, ``round_trip_ms``), ``rating`` (``value`` 0-100,
``shown_ms``, ``answered_ms``), ``questionnaire`` (``answers``: 12 integers 1-7), ``next``.
Out: ``hello``, ``phase``, ``state``.
"""

from __future__ import annotations

import asyncio
import json
import logging
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

from trust_av_planner.errors import TrustAvPlannerError

LOG = logging.getLogger(__name__)
PAGES = {'/': ('index.html', 'text/html; charset=utf-8'),
         '/drive.js': ('drive.js', 'text/javascript; charset=utf-8'),
         '/drive.css': ('drive.css', 'text/css; charset=utf-8')}
"""Path -> (file in ``trust_av_planner/drive/web``, content type)."""
MESSAGE_TYPES = frozenset({'ready', 'input', 'latency', 'rating', 'questionnaire', 'next'})
MAX_MESSAGE_BYTES = 4096


class ServerError(TrustAvPlannerError):
    """The server cannot start (e.g. the port is taken); the message says why."""


def page_file(name: str) -> bytes:
    """One of the page's files, as shipped in the package."""
    return resources.files('trust_av_planner.drive').joinpath('web', name).read_bytes()


def parse_message(text: str | bytes) -> dict[str, Any]:
    """One message from the page.

    Raises:
        ValueError: not a JSON object with a known ``type`` (named).
    """
    data = json.loads(text)
    if not isinstance(data, dict) or data.get('type') not in MESSAGE_TYPES:
        raise ValueError(f'not a page message: {str(text)[:80]!r}')
    return data


class DriveServer:
    """The page and its WebSocket, served from a background thread.

    Args:
        on_message: called in the server's thread with each message from the page and the
            wall time it arrived (ns); it must return quickly.
        on_connect: called in the server's thread when a page connects (to greet it).
        host: address to listen on.
        port: TCP port (0: any free port).
    """

    def __init__(self, on_message: Callable[[dict[str, Any], int], None],
                 on_connect: Callable[[], None], *, host: str = '127.0.0.1',
                 port: int = 0) -> None:
        self.on_message = on_message
        self.on_connect = on_connect
        self.host, self.port = host, port
        self.clients: set[ServerConnection] = set()
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

    def _http(self, _connection: ServerConnection, request: Request) -> Response | None:
        path = request.path.split('?', 1)[0]
        if path == '/ws':
            return None                           # the WebSocket handshake goes on
        if path == '/favicon.ico':
            return Response(HTTPStatus.NO_CONTENT, 'No Content', Headers(), b'')
        if path not in PAGES:
            return Response(HTTPStatus.NOT_FOUND, 'Not Found',
                            Headers([('Content-Type', 'text/plain')]), b'not found\n')
        name, kind = PAGES[path]
        body = page_file(name)
        return Response(HTTPStatus.OK, 'OK', Headers([
            ('Content-Type', kind), ('Content-Length', str(len(body))),
            ('Cache-Control', 'no-store')]), body)

    async def _handler(self, connection: ServerConnection) -> None:
        self.clients.add(connection)
        self.on_connect()
        try:
            async for text in connection:
                arrived = time.time_ns()
                try:
                    message = parse_message(text)
                except ValueError as err:
                    LOG.warning('dropped a message from the page: %s', err)
                    continue
                self.on_message(message, arrived)
        except ConnectionClosed:
            pass                                  # a closed tab: counted below
        finally:
            self.clients.discard(connection)
            self.disconnects += 1

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

    def close_clients(self) -> None:
        """Drop every page connection (what a lost network does; tests)."""
        loop = self._loop
        if loop is not None:
            for client in list(self.clients):
                asyncio.run_coroutine_threadsafe(client.close(), loop)

    def stop(self) -> None:
        """Stop serving and join the thread."""
        loop, server = self._loop, self._server
        if loop is None or server is None or self._thread is None:
            return

        async def shut() -> None:
            server.close()
            await server.wait_closed()
        asyncio.run_coroutine_threadsafe(shut(), loop).result(timeout=10)
        loop.call_soon_threadsafe(loop.stop)
        self._thread.join(timeout=10)
