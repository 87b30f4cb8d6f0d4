"""The channels of a run log: their schemas and channel records, registered with the MCAP
writer when they are first needed (topics and schemas are described in :mod:`.schemas`)."""

from __future__ import annotations

from typing import Any

from mcap.writer import Writer

from .schemas import SCENE_TOPIC_PREFIX, SCHEMAS, schema_bytes


class Channels:
    """The channel ids of one log by topic: the JSON topics of ``schemas`` (default
    :data:`.schemas.SCHEMAS`; a scenario's: :func:`.schemas.schemas_for`), all registered
    at once when the file is opened, then a scene topic per game, registered (with the
    Foxglove SDK's ``foxglove.SceneUpdate`` schema, the first time) when that game's first
    scene is written."""

    def __init__(self, writer: Writer, schemas: dict[str, dict[str, Any]] | None = None) -> None:
        self._writer = writer
        self._ids = {
            topic: writer.register_channel(
                topic,
                "json",
                writer.register_schema(schema["title"], "jsonschema", schema_bytes(schema)),
            )
            for topic, schema in (SCHEMAS if schemas is None else schemas).items()
        }
        self._schemas: dict[str, int] = {}

    def __getitem__(self, topic: str) -> int:
        """The id of ``topic``'s channel; a scene topic's channel is registered on demand."""
        channel = self._ids.get(topic)
        if channel is None:
            if not topic.startswith(SCENE_TOPIC_PREFIX):
                raise KeyError(topic)
            from .sdk import register_scene_channel

            channel = self._ids[topic] = register_scene_channel(self._writer, topic, self._schemas)
        return channel
