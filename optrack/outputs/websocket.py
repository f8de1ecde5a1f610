"""A WebSocket server (``websockets``) pushing the JSON documents to browsers.

Every connected client receives each tracks document and heartbeat as one
text message, exactly the JSON of the UDP output. The server runs its own
asyncio loop in a thread; :meth:`WebSocketServer.send` may be called from
any thread and never waits for a slow client (``websockets.broadcast``
skips a client whose buffer is full).
"""

from __future__ import annotations

import asyncio
import logging
import threading

from websockets.asyncio.server import Server, ServerConnection, broadcast, serve

from optrack.net.messages import DestinationStatus
from optrack.outputs.udp import OutputError

__all__ = ["WebSocketServer"]

log = logging.getLogger("optrack.outputs")


class WebSocketServer:
    """Listens on ``host:port`` (port 0: any free port; see :attr:`port`)."""

    def __init__(self, host: str, port: int, start_timeout_s: float = 5.0) -> None:
        self.host = host
        self.sent = 0
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
        async with serve(self._client, host, port, compression=None) as server:
            self._server = server
            self._ready.set()
            await self._stopped

    async def _client(self, connection: ServerConnection) -> None:
        # Clients only listen; anything they send is read and ignored.
        async for _ in connection:
            pass

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
            clients=self.clients,
        )

    def close(self) -> None:
        stopped = self._stopped
        if stopped is not None and not self._loop.is_closed():
            try:
                self._loop.call_soon_threadsafe(lambda: stopped.done() or stopped.set_result(None))
            except RuntimeError:
                pass
        self._thread.join(timeout=5.0)
