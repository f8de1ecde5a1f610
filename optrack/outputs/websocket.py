"""A WebSocket server (``websockets``) pushing the JSON documents to browsers.

Every connected client receives each tracks document and heartbeat as one
text message, exactly the JSON of the UDP output. The server runs its own
asyncio loop in a thread; :meth:`WebSocketServer.send` may be called from
any thread and never waits for a slow client (``websockets.broadcast``
skips a client whose buffer is full).

A browser says which page opened the connection (``Origin``): only pages of
``origins`` may connect (by default files opened from disk, whose origin is
``null``, and pages served by this computer, ``localhost``); a client that
sends no ``Origin`` is not a browser page and is not asked. With a ``token``
every client must also give ``?token=...`` in its URL. Refused clients and
messages over ``max_size`` (the connection is closed) are counted, and each
kind is logged once.
"""

from __future__ import annotations

import asyncio
import hmac
import logging
import threading
from collections.abc import Sequence
from http import HTTPStatus
from urllib.parse import parse_qs, urlsplit

from websockets.asyncio.server import Server, ServerConnection, broadcast, serve
from websockets.exceptions import ConnectionClosed
from websockets.frames import CloseCode
from websockets.http11 import Request, Response

from optrack.net.messages import DestinationStatus
from optrack.outputs.udp import OutputError

__all__ = ["DEFAULT_ORIGINS", "WebSocketServer", "origin_allowed"]

log = logging.getLogger("optrack.outputs")

# pages that may connect: files opened from disk ("null") and pages served by this computer
DEFAULT_ORIGINS = ("null", "http://localhost", "http://127.0.0.1", "http://[::1]")


def origin_allowed(origin: str | None, allowed: Sequence[str]) -> bool:
    """Whether a browser page of ``origin`` may connect: no ``Origin`` (not a page), an
    entry equal to it, ``*``, or an entry without a port naming its scheme and host (any
    port; ``http://localhost`` also allows ``https://localhost``)."""
    if origin is None or "*" in allowed or origin in allowed:
        return True
    parts = urlsplit(origin)
    try:
        host = parts.hostname
    except ValueError:
        return False
    if not host:
        return False
    host = f"[{host}]" if ":" in host else host
    secure = {"https": "http", "wss": "ws"}.get(parts.scheme, parts.scheme)
    return any(f"{scheme}://{host}" in allowed for scheme in {parts.scheme, secure})


class WebSocketServer:
    """Listens on ``host:port`` (port 0: any free port; see :attr:`port`)."""

    def __init__(
        self,
        host: str,
        port: int,
        start_timeout_s: float = 5.0,
        *,
        origins: Sequence[str] = DEFAULT_ORIGINS,
        token: str = "",
        max_size: int = 1 << 20,
    ) -> None:
        self.host = host
        self.sent = 0
        self.origins = tuple(origins)
        self.token = token
        self.max_size = max_size
        self.refused = 0  # clients of a foreign Origin or without the token
        self.oversize = 0  # connections closed for a message over max_size
        self.last_error = ""
        self._logged: set[str] = set()
        self._loop = asyncio.new_event_loop()
        self._server: Server | None = None
        self._ready = threading.Event()
        self._stopped: asyncio.Future[None] | None = None
        self._error: BaseException | None = None
        self._thread = threading.Thread(
            target=self._run, args=(host, port), name="websocket", daemon=True
        )
        self._thread.start()
        if not self._ready.wait(start_timeout_s) or self._error is not None:
            self.close()
            reason = self._error.strerror if isinstance(self._error, OSError) else self._error
            raise OutputError(
                f"the WebSocket output cannot listen on {host}:{port} ({reason or 'timed out'}); "
                "choose a free port (outputs.websocket)."
            )
        assert self._server is not None
        self.port = int(self._server.sockets[0].getsockname()[1])
        self.address = f"{host}:{self.port}"

    def _run(self, host: str, port: int) -> None:
        asyncio.set_event_loop(self._loop)
        try:
            self._loop.run_until_complete(self._main(host, port))
        except BaseException as error:  # start-up failure: reported by __init__
            self._error = error
            self._ready.set()
        finally:
            self._loop.close()

    async def _main(self, host: str, port: int) -> None:
        self._stopped = self._loop.create_future()
        async with serve(
            self._client,
            host,
            port,
            compression=None,
            process_request=self._admit,
            max_size=self.max_size,
        ) as server:
            self._server = server
            self._ready.set()
            await self._stopped

    def _admit(self, connection: ServerConnection, request: Request) -> Response | None:
        """Refuse (403, counted) a page of a foreign Origin or a client without the token."""
        origin = request.headers.get("Origin")
        if not origin_allowed(origin, self.origins):
            reason = f"a page of {origin} (not in the allowed origins) was refused"
        elif self.token and not hmac.compare_digest(
            (parse_qs(urlsplit(request.path).query).get("token") or [""])[0], self.token
        ):
            reason = "a client without the right ?token= was refused"
        else:
            return None
        self._count("refused", reason)
        return connection.respond(HTTPStatus.FORBIDDEN, "refused by optrack's WebSocket output\n")

    async def _client(self, connection: ServerConnection) -> None:
        # Clients only listen; anything they send is read and ignored.
        try:
            async for _ in connection:
                pass
        except ConnectionClosed as closed:
            if closed.sent is not None and closed.sent.code == CloseCode.MESSAGE_TOO_BIG:
                self._count("oversize", f"a client's message over {self.max_size} bytes closed it")

    def _count(self, kind: str, reason: str) -> None:
        setattr(self, kind, getattr(self, kind) + 1)
        self.last_error = reason
        if kind not in self._logged:
            self._logged.add(kind)
            log.warning("WebSocket output: %s (further such clients are only counted)", reason)

    @property
    def clients(self) -> int:
        server = self._server
        return len(server.connections) if server is not None else 0

    def send(self, text: str) -> None:
        """Push one JSON document to every client (thread-safe, never blocks)."""
        if self._server is None or self._loop.is_closed():
            return
        try:
            self._loop.call_soon_threadsafe(self._broadcast, text)
        except RuntimeError:  # the loop closed meanwhile
            pass

    def _broadcast(self, text: str) -> None:
        assert self._server is not None
        connections = self._server.connections
        if connections:
            broadcast(connections, text)
            self.sent += 1

    def status(self) -> DestinationStatus:
        return DestinationStatus(
            kind="websocket",
            address=f"ws://{self.address}" if hasattr(self, "address") else "",
            sent=self.sent,
            errors=self.refused + self.oversize,
            clients=self.clients,
            last_error=self.last_error,
        )

    def close(self) -> None:
        stopped = self._stopped
        if stopped is not None and not self._loop.is_closed():
            try:
                self._loop.call_soon_threadsafe(lambda: stopped.done() or stopped.set_result(None))
            except RuntimeError:
                pass
        self._thread.join(timeout=5.0)
