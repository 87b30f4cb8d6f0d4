"""A WebSocket relay that lets clients speak either name of Foxglove's protocol.

Foxglove renamed its WebSocket subprotocol from ``foxglove.websocket.v1`` to
``foxglove.sdk.v1`` without changing a message; the SDK's server accepts only the new name,
and Foxglove's own client library (``@foxglove/ws-protocol``) and older apps offer only the
old one, so they were dropped with "handshake failed". :class:`Relay` listens on the public
address, accepts a client offering either name (the new one when it offers both), and for
each client opens one connection to the SDK's server on the loopback interface, then
forwards every frame both ways unchanged (text stays text, binary stays binary).

Backpressure is kept: the relay awaits each send, so a slow client stops the relay reading
from the SDK, whose own per-client queue then drops the oldest messages as it would for a
direct client. The relay runs an asyncio loop in a daemon thread of its own.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading

from websockets.asyncio.client import connect
from websockets.asyncio.connection import Connection
from websockets.asyncio.server import Server, ServerConnection, serve
from websockets.exceptions import ConnectionClosed, WebSocketException

SUBPROTOCOLS = ("foxglove.sdk.v1", "foxglove.websocket.v1")
"""The names accepted from clients, preferred first; the SDK's server speaks the first."""


async def _forward(source: Connection, target: Connection) -> None:
    """Send every frame from ``source`` to ``target`` until either closes."""
    with contextlib.suppress(ConnectionClosed):
        async for frame in source:
            await target.send(frame)


class Relay:
    """Accept Foxglove clients on ``host:port`` (port 0: any free one) and relay each to the
    SDK server at ``upstream`` (``ws://127.0.0.1:PORT``). An address that cannot be had
    raises the ``OSError`` of the bind; :meth:`close` stops the relay and its clients."""

    def __init__(self, host: str, port: int, upstream: str) -> None:
        self.upstream = upstream
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(
            target=self._loop.run_forever, name="foxglove-relay", daemon=True
        )
        self._thread.start()
        try:
            self._server: Server = asyncio.run_coroutine_threadsafe(
                self._serve(host, port), self._loop
            ).result()
        except BaseException:
            self._stop_loop()
            raise
        self.port: int = self._server.sockets[0].getsockname()[1]

    async def _serve(self, host: str, port: int) -> Server:
        return await serve(
            self._relay,
            host,
            port,
            subprotocols=list(SUBPROTOCOLS),
            max_size=None,
            compression=None,
        )

    async def _relay(self, client: ServerConnection) -> None:
        try:
            upstream = await connect(
                self.upstream,
                subprotocols=[SUBPROTOCOLS[0]],
                max_size=None,
                compression=None,
                open_timeout=10,
            )
        except (OSError, WebSocketException, TimeoutError):
            await client.close(1011, "the Foxglove server is not reachable")
            return
        async with upstream:
            pumps = [
                asyncio.create_task(_forward(client, upstream)),
                asyncio.create_task(_forward(upstream, client)),
            ]
            _, pending = await asyncio.wait(pumps, return_when=asyncio.FIRST_COMPLETED)
            for task in pending:
                task.cancel()
            await asyncio.gather(*pending, return_exceptions=True)

    def _stop_loop(self) -> None:
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join()
        self._loop.run_until_complete(self._loop.shutdown_asyncgens())
        self._loop.close()

    def close(self) -> None:
        """Stop accepting, disconnect every client and end the relay's thread; idempotent."""
        if self._loop.is_closed():
            return
        with contextlib.suppress(Exception):
            asyncio.run_coroutine_threadsafe(self._shut(), self._loop).result(10)
        self._stop_loop()

    async def _shut(self) -> None:
        self._server.close()
        await self._server.wait_closed()
        # handshakes and relays still under way end here, not as coroutines never finished
        tasks = asyncio.all_tasks() - {asyncio.current_task()}
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
