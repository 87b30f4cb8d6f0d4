"""The ``/train/update`` messages: one learner update's metrics with the run's counters,
and the wall-clock rate of vector steps between two updates (``steps_per_s``); the
``/plot/update`` point of the same update is made from the same document
(:func:`.curve.update_point`)."""

from __future__ import annotations

import json
import time
from typing import Any

from .curve import update_point
from .jsontext import json_value
from .schemas import PLOT_UPDATE_TOPIC, UPDATE_TOPIC


class StepRate:
    """Measures vector steps per second of wall-clock time from one update to the next."""

    def __init__(self, steps: int) -> None:
        self._mark = (time.perf_counter(), steps)

    def measure(self, steps: int, games: int) -> float | None:
        """Game steps per second (``games`` per vector step) since the previous call (or
        since the start), with ``steps`` vector steps taken so far; ``None`` if no time
        has passed on the clock."""
        now, (then, before) = time.perf_counter(), self._mark
        self._mark = (now, steps)
        return (steps - before) * games / (now - then) if now > then else None


def update_document(
    update: int,
    metrics: dict[str, Any],
    env_steps: int,
    episodes: int,
    steps_per_s: float | None,
) -> dict[str, Any]:
    """One update as a JSON-ready document: ``metrics`` (any key; values made JSON),
    ``steps_per_s`` unless ``metrics`` has it (or it is ``None``), and the counters
    ``update``, ``env_steps`` and ``episodes``."""
    doc = {k: json_value(v) for k, v in metrics.items()}
    if "steps_per_s" not in doc and steps_per_s is not None:
        doc["steps_per_s"] = steps_per_s
    doc.update(update=int(update), env_steps=env_steps, episodes=episodes)
    return doc


def update_messages(
    update: int,
    metrics: dict[str, Any],
    env_steps: int,
    episodes: int,
    steps_per_s: float | None,
) -> list[tuple[str, bytes]]:
    """``(topic, data)`` of one update: its ``/train/update`` JSON (:func:`update_document`),
    then its ``/plot/update`` point."""
    doc = update_document(update, metrics, env_steps, episodes, steps_per_s)
    full = json.dumps(doc, separators=(",", ":")).encode()
    return [(UPDATE_TOPIC, full), (PLOT_UPDATE_TOPIC, update_point(doc))]
