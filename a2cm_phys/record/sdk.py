"""The Foxglove SDK (``foxglove-sdk``) where the package meets it: its schemas in the run
log, and its WebSocket server for live views.

In a log: the SDK's file sink cannot share the trainer's MCAP file, so the SDK's messages
are encoded by the SDK (``msg.encode()``: protobuf) and written through the ``mcap`` writer
under the SDK's own schema: name ``foxglove.SceneUpdate``, encoding ``protobuf``, data the
SDK's ``FileDescriptorSet`` (:func:`register_scene_channel`). Foxglove reads them as its own.

On the wire: :class:`FoxgloveServer` starts the SDK's WebSocket server in a context of its
own, so that several servers (tests, a sweep's runs) never share channels, on the loopback
interface behind a :class:`~a2cm_phys.record.relay.Relay` on the public address: the SDK
accepts only the protocol name ``foxglove.sdk.v1``, the relay also Foxglove's older name
``foxglove.websocket.v1`` (the same protocol), which Foxglove's own client library offers.
Its channels' ``log`` never blocks: the SDK queues each client's messages on its own
threads, dropping the oldest when a client falls behind.
"""

from __future__ import annotations

from typing import Any

import foxglove
from foxglove.channels import SceneUpdateChannel
from foxglove.messages import SceneUpdate
from mcap.writer import Writer

from ..base.errors import UserError
from .relay import Relay
from .schemas import schema_bytes

DEFAULT_HOST, DEFAULT_PORT = "127.0.0.1", 8765
"""Where a server listens unless told: this machine only, Foxglove's usual port."""
PROTOBUF = "protobuf"
"""The message and schema encoding of the SDK's messages."""
SCENE_SCHEMA_NAME = "foxglove.SceneUpdate"
"""The schema name of scene channels (Foxglove's own)."""


def scene_schema() -> tuple[str, str, bytes]:
    """``(name, encoding, data)`` of the SDK's ``foxglove.SceneUpdate`` schema."""
    schema = SceneUpdate.get_schema()
    return schema.name, schema.encoding, bytes(schema.data)


def register_scene_channel(writer: Writer, topic: str, schemas: dict[str, int]) -> int:
    """Register a ``foxglove.SceneUpdate`` channel on ``topic`` with ``writer`` (the schema
    once per file: ``schemas`` keeps its id by name); its id."""
    name, encoding, data = scene_schema()
    if name not in schemas:
        schemas[name] = writer.register_schema(name, encoding, data)
    return writer.register_channel(topic, PROTOBUF, schemas[name])


def address(text: str | None, option: str) -> tuple[str, int]:
    """``(host, port)`` of an option's ``[[HOST:]PORT]`` value: ``None`` or empty for
    :data:`DEFAULT_HOST` and :data:`DEFAULT_PORT`, ``PORT``, ``HOST:PORT`` or ``HOST:``
    (port 0: any free one); a :class:`UserError` naming ``option`` for anything else."""
    if not text:
        return DEFAULT_HOST, DEFAULT_PORT
    host, sep, port = text.rpartition(":")
    if not sep:
        host, port = DEFAULT_HOST, text
    port = port or str(DEFAULT_PORT)
    if not port.isdigit() or not 0 <= int(port) <= 65535:
        raise UserError(f"{option}: {text!r} is not [[HOST:]PORT] (a port is 0 to 65535)")
    return host or DEFAULT_HOST, int(port)


class FoxgloveServer:
    """The SDK's WebSocket server with a context of its own, reached through a relay on
    ``host:port`` (port 0: any free one) that accepts both names of the protocol. A port
    that cannot be had (busy, or not ours to bind) is a
    :class:`~a2cm_phys.base.errors.UserError` naming it. ``message_backlog`` is how many
    messages each client may fall behind before its oldest are dropped."""

    def __init__(self, host: str, port: int, name: str, message_backlog: int = 1024) -> None:
        self.context = foxglove.Context()
        try:
            self.server = foxglove.start_server(
                name=name,
                host="127.0.0.1",
                port=0,
                context=self.context,
                message_backlog_size=message_backlog,
            )
        except (RuntimeError, OSError, ValueError, OverflowError) as err:
            reason = str(err).removeprefix("FoxgloveError: ")
            raise UserError(f"cannot start the Foxglove server: {reason}") from None
        try:
            self.relay = Relay(host, port, f"ws://127.0.0.1:{self.server.port}")
        except (OSError, ValueError, OverflowError) as err:
            self.server.stop()
            reason = err.strerror if isinstance(err, OSError) and err.strerror else str(err)
            raise UserError(f"cannot serve Foxglove on {host}:{port}: {reason}") from None
        self.host, self.port = host, self.relay.port

    @property
    def url(self) -> str:
        """The address a Foxglove client opens (``ws://host:port``)."""
        return f"ws://{self.host}:{self.port}"

    def scene_channel(self, topic: str) -> Any:
        """A ``foxglove.SceneUpdate`` channel on ``topic`` (the SDK's typed channel)."""
        return SceneUpdateChannel(topic, context=self.context)

    def json_channel(self, topic: str, schema: dict[str, Any]) -> Any:
        """A JSON channel on ``topic`` with the JSON schema ``schema`` (named by its
        title), for messages given as encoded bytes."""
        sdk_schema = foxglove.Schema(
            name=schema["title"], encoding="jsonschema", data=schema_bytes(schema)
        )
        return foxglove.Channel(
            topic, schema=sdk_schema, message_encoding="json", context=self.context
        )

    def close(self) -> None:
        """Stop the relay and the server (clients are disconnected); idempotent."""
        self.relay.close()
        self.server.stop()
