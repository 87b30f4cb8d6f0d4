"""Topic names and JSON schemas of the run log ``episodes.mcap`` (all channels JSON-encoded).

| topic | schema | one message per |
| --- | --- | --- |
| ``/episodes/trajectories`` | ``a2cm_phys.TrajectoryBlock`` | block of logged episodes |
| ``/episodes/summaries`` | ``a2cm_phys.EpisodeSummaryBlock`` | block of finished episodes |
| ``/train/update`` | ``a2cm_phys.UpdateMetrics`` | learner update |
| ``/scene/env_<i>`` | ``foxglove.SceneUpdate`` | step of a drawn episode played in game ``i`` |

Episodes are written in *blocks* (the episodes that finished since the previous block,
every few seconds at most), column-wise: per-episode arrays, and the per-step arrays of all
the block's episodes concatenated in episode order (``length`` splits them). Every
finished episode has a summary; every ``log_every``-th (by id) a trajectory.

Times: the log's clock is the run's simulated time. All games of a vector env step in
lockstep, one step being :func:`step_seconds` of simulated time (1 s on the grid, the
control period ``physics.dt`` in physics mode: 1 s for discrete moves, 0.1 s by default
for continuous commands), so vector step ``k`` happens at ``k · step_seconds`` in every
game: that is each game's cumulative simulated time, and the clock of every ``log_time``.
A block is logged at the end of its last episode, an update at the step it was recorded, a
scene frame at the time of the state it shows (scenes thus play at the control rate).
Each channel's log times are non-decreasing. The Foxglove schema is generated here: a
subset of ``foxglove.SceneUpdate`` with every field the official schema requires.

Format versions (metadata ``format``; :mod:`.reader` reads both):

- ``a2cm_phys.episodes/1``: integer actions only; one step = 1 s.
- ``a2cm_phys.episodes/2``: continuous commands as float actions; ``dt`` and the clock
  follow the control period; a learned evader's reward and return (``evader_reward``,
  ``evader_return``); sparse update metrics (``exploit_*``) documented.
"""

from __future__ import annotations

import json
from typing import Any

from ..config import Scenario

TRAJECTORY_TOPIC = "/episodes/trajectories"
"""Blocks of logged episodes, step by step (:data:`TRAJECTORY_SCHEMA`)."""
SUMMARY_TOPIC = "/episodes/summaries"
"""Blocks of finished episodes' summaries (:data:`SUMMARY_SCHEMA`)."""
UPDATE_TOPIC = "/train/update"
"""One message per learner update (:data:`UPDATE_SCHEMA`)."""
SCENE_TOPIC_PREFIX = "/scene/env_"
"""``foxglove.SceneUpdate`` frames of the drawn episodes of game ``i``: ``/scene/env_<i>``."""
METADATA_NAME = "a2cm_phys"
"""Name of the MCAP metadata record holding the run's scenario, config and provenance."""
FORMAT = "a2cm_phys.episodes/2"
"""Format tag stored in the metadata; bump on incompatible changes (history above)."""
FORMAT_VERSION = 2
"""The version number in :data:`FORMAT`: the newest this package reads."""


def step_seconds(scenario: Scenario) -> float:
    """Simulated seconds per environment step: 1 on the grid, ``physics.dt`` in physics mode."""
    if scenario.mode != "physics" or scenario.physics.dt is None:
        return 1.0
    return float(scenario.physics.dt)


def scene_topic(env: int) -> str:
    """The SceneUpdate topic of the episodes played in game ``env`` (one at a time)."""
    return f"{SCENE_TOPIC_PREFIX}{env}"


def _array(item: Any, doc: str) -> dict[str, Any]:
    if isinstance(item, str):
        item = {"type": item}
    return {"type": "array", "items": item, "description": doc}


def _rows(item: str, doc: str) -> dict[str, Any]:
    return _array({"type": "array", "items": {"type": item}}, doc)


_SEEDS = _array(
    {"type": "string", "pattern": "^[0-9]+$"},
    "episode seeds (uint64 as decimal strings: exact in any JSON reader)",
)
_PER_EPISODE = {
    "episode": _array("integer", "episode ids (numbered in order of finishing)"),
    "env": _array("integer", "game index in the vector env"),
    "seed": _SEEDS,
    "length": _array("integer", "steps taken"),
}

TRAJECTORY_SCHEMA: dict[str, Any] = {
    "title": "a2cm_phys.TrajectoryBlock",
    "description": "Logged episodes, step by step, column-wise. Each re-simulates from its seed "
    "and the logged actions (the pursuers', and a learned evader's). State arrays hold "
    "length+1 rows per episode (its start, then the state after each step); step arrays "
    "length rows; both concatenated in episode order. Agents: pursuers in order, then the "
    "evader.",
    "type": "object",
    "properties": {
        **_PER_EPISODE,
        "t0": _array("number", "run time of each episode's start (s)"),
        "dt": {"type": "number", "description": "simulated seconds per step"},
        "time": _array("number", "state rows: simulated time since the episode's start (s)"),
        "positions": _rows("number", "state rows: x0,y0,x1,y1,… (grid: cells; physics: m)"),
        "velocities": _rows("number", "physics only; state rows: vx0,vy0,… (m/s)"),
        "actions": _rows(
            "number",
            "step rows: each pursuer's action, then the evader's. Discrete control: N + 1 "
            "integer moves. Continuous control: 2(N + 1) numbers vx0,vy0,…,vxE,vyE, the "
            "commands as given to the env (fractions of max_speed, before clipping to the "
            "unit disc), each the shortest text that reads back as the same float64 (float32 "
            "commands are exact float64 values); null for a non-finite one",
        ),
        "reward": _array("number", "step rows: raw team reward (the pursuers')"),
        "evader_reward": _array(
            "number", "learned evader only; step rows: the evader's reward (rewards.evader)"
        ),
        "captured": _array("boolean", "step rows: capture in this step"),
        "collisions": _array("integer", "step rows: pursuer pairs that collided"),
        "wall_contacts": _array("integer", "step rows: pursuer moves/contacts against a wall"),
        "events": _array(
            {
                "type": "array",
                "items": {
                    "type": "array",
                    "prefixItems": [
                        {"type": "string"},
                        {"type": "string"},
                        {"type": "string"},
                        {"type": "integer"},
                    ],
                },
            },
            "physics only; per episode, the contact events [kind, a, b, step] that began",
        ),
    },
    "required": [
        "episode",
        "env",
        "seed",
        "length",
        "t0",
        "dt",
        "time",
        "positions",
        "actions",
        "reward",
        "captured",
        "collisions",
        "wall_contacts",
    ],
}
"""Schema of :data:`TRAJECTORY_TOPIC` messages."""

SUMMARY_SCHEMA: dict[str, Any] = {
    "title": "a2cm_phys.EpisodeSummaryBlock",
    "description": "Finished episodes (all of them), one array entry per episode.",
    "type": "object",
    "properties": {
        **_PER_EPISODE,
        "return": _array("number", "sum of the raw team rewards (the pursuers' return)"),
        "evader_return": _array("number", "learned evader only: the sum of its rewards"),
        "captured": _array("boolean", "ended by a capture"),
        "truncated": _array("boolean", "reached max_steps"),
        "collision_terminated": _array("boolean", "ended by a collision"),
        "collisions": _array("integer", "pursuer collisions in the episode"),
        "wall_contacts": _array("integer", "wall contacts in the episode"),
        "t0": _array("number", "run time of the start (s)"),
        "t1": _array("number", "run time of the end (s)"),
        "logged": _array("boolean", "its trajectory is in the log"),
    },
    "required": [
        "episode",
        "env",
        "seed",
        "length",
        "return",
        "captured",
        "truncated",
        "collision_terminated",
        "collisions",
        "wall_contacts",
        "t0",
        "t1",
        "logged",
    ],
}
"""Schema of :data:`SUMMARY_TOPIC` messages."""

UPDATE_METRICS = (
    "policy_loss",
    "value_loss",
    "entropy",
    "mean_advantage",
    "grad_norm",
    "steps_per_s",
)
"""Metrics the trainer is expected to report per update (others are allowed)."""

SPARSE_METRICS = {
    "exploit_worst_case": "grid self-play, every K updates: the evader's exact best response "
    "to the current pursuers, their worst-case expected capture time (steps)",
    "exploit_pursuers_br": "grid self-play, every K updates: the pursuers' exact best response "
    "to the current learned evader, its expected capture time (steps)",
}
"""Metrics present only in the updates where the trainer computes them (absent elsewhere)."""

UPDATE_SCHEMA: dict[str, Any] = {
    "title": "a2cm_phys.UpdateMetrics",
    "description": "One learner update: counters, then the trainer's metrics (null if not finite).",
    "type": "object",
    "properties": {
        "update": {"type": "integer"},
        "env_steps": {"type": "integer", "description": "environment steps so far (all games)"},
        "episodes": {"type": "integer", "description": "episodes finished so far"},
        **{k: {"type": ["number", "null"]} for k in UPDATE_METRICS},
        **{
            k: {"type": ["number", "null"], "description": doc} for k, doc in SPARSE_METRICS.items()
        },
    },
    "additionalProperties": {"type": ["number", "null", "string", "boolean"]},
    "required": ["update", "env_steps", "episodes"],
}
"""Schema of :data:`UPDATE_TOPIC` messages."""


# --------------------------------------------------------------------------- foxglove


def _obj(title: str, props: dict[str, Any]) -> dict[str, Any]:
    return {"title": title, "type": "object", "properties": props, "required": list(props)}


_NUM = {"type": "number"}
_TIME = {
    "type": "object",
    "title": "time",
    "properties": {
        "sec": {"type": "integer", "minimum": 0},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999},
    },
    "required": ["sec", "nsec"],
}
_DURATION = {
    "type": "object",
    "title": "duration",
    "properties": {
        "sec": {"type": "integer"},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999},
    },
    "required": ["sec", "nsec"],
}
_VEC3 = _obj("foxglove.Vector3", {"x": _NUM, "y": _NUM, "z": _NUM})
_POINT3 = _obj("foxglove.Point3", {"x": _NUM, "y": _NUM, "z": _NUM})
_QUAT = _obj("foxglove.Quaternion", {"x": _NUM, "y": _NUM, "z": _NUM, "w": _NUM})
_POSE = _obj("foxglove.Pose", {"position": _VEC3, "orientation": _QUAT})
_COLOR = _obj("foxglove.Color", {"r": _NUM, "g": _NUM, "b": _NUM, "a": _NUM})
_ARRAY = {"type": "array", "items": {"type": "object"}}


def _list(item: dict[str, Any]) -> dict[str, Any]:
    return {"type": "array", "items": item}


_PRIMITIVES = {
    "arrows": _list(
        _obj(
            "foxglove.ArrowPrimitive",
            {
                "pose": _POSE,
                "shaft_length": _NUM,
                "shaft_diameter": _NUM,
                "head_length": _NUM,
                "head_diameter": _NUM,
                "color": _COLOR,
            },
        )
    ),
    "cubes": _list(_obj("foxglove.CubePrimitive", {"pose": _POSE, "size": _VEC3, "color": _COLOR})),
    "spheres": _list(
        _obj("foxglove.SpherePrimitive", {"pose": _POSE, "size": _VEC3, "color": _COLOR})
    ),
    "cylinders": _ARRAY,
    "lines": _list(
        _obj(
            "foxglove.LinePrimitive",
            {
                "type": {"type": "integer", "enum": [0, 1, 2]},
                "pose": _POSE,
                "thickness": _NUM,
                "scale_invariant": {"type": "boolean"},
                "points": _list(_POINT3),
                "color": _COLOR,
                "colors": _list(_COLOR),
                "indices": _list({"type": "integer", "minimum": 0}),
            },
        )
    ),
    "triangles": _ARRAY,
    "texts": _list(
        _obj(
            "foxglove.TextPrimitive",
            {
                "pose": _POSE,
                "billboard": {"type": "boolean"},
                "font_size": _NUM,
                "scale_invariant": {"type": "boolean"},
                "color": _COLOR,
                "text": {"type": "string"},
            },
        )
    ),
    "models": _ARRAY,
}

SCENE_SCHEMA: dict[str, Any] = {
    "title": "foxglove.SceneUpdate",
    "description": "An update to the entities displayed in a 3D scene",
    "type": "object",
    "properties": {
        "deletions": _list(
            _obj(
                "foxglove.SceneEntityDeletion",
                {
                    "timestamp": _TIME,
                    "type": {"type": "integer", "enum": [0, 1]},
                    "id": {"type": "string"},
                },
            )
        ),
        "entities": _list(
            _obj(
                "foxglove.SceneEntity",
                {
                    "timestamp": _TIME,
                    "frame_id": {"type": "string"},
                    "id": {"type": "string"},
                    "lifetime": _DURATION,
                    "frame_locked": {"type": "boolean"},
                    "metadata": _list(
                        _obj(
                            "foxglove.KeyValuePair",
                            {"key": {"type": "string"}, "value": {"type": "string"}},
                        )
                    ),
                    **_PRIMITIVES,
                },
            )
        ),
    },
    "required": ["deletions", "entities"],
}
"""Schema stored with the scene topics (a faithful subset of Foxglove's)."""

SCHEMAS: dict[str, dict[str, Any]] = {
    TRAJECTORY_TOPIC: TRAJECTORY_SCHEMA,
    SUMMARY_TOPIC: SUMMARY_SCHEMA,
    UPDATE_TOPIC: UPDATE_SCHEMA,
}
"""Schema of each fixed topic (scene topics use :data:`SCENE_SCHEMA`)."""


def schema_bytes(schema: dict[str, Any]) -> bytes:
    """The schema as stored in the MCAP Schema record (compact JSON)."""
    return json.dumps(schema, separators=(",", ":")).encode()
