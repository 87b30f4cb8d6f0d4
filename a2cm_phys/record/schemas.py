"""Topic names and JSON schemas of the run log ``episodes.mcap`` (JSON-encoded channels;
the scenes are protobuf).

| topic | schema | one message per |
| --- | --- | --- |
| ``/episodes/trajectories`` | ``a2cm_phys.TrajectoryBlock`` | block of logged episodes |
| ``/episodes/summaries`` | ``a2cm_phys.EpisodeSummaryBlock`` | block of finished episodes |
| ``/train/update`` | ``a2cm_phys.UpdateMetrics`` | learner update |
| ``/plot/episodes`` | ``a2cm_phys.EpisodePoint`` | :data:`PLOT_EVERY` finished episodes |
| ``/plot/update`` | ``a2cm_phys.UpdatePoint`` | learner update |
| ``/scene/env_<i>`` | ``foxglove.SceneUpdate`` | state of a drawn episode played in game ``i`` |

The first three are the readers' source (:mod:`.reader`). The ``/plot`` topics repeat what
they hold as plain numbers, for Foxglove's Plot panel: its JSON-schema reader takes one
plain type per field (no ``["number", "null"]``, no arrays of arrays), which the summaries'
blocks and the updates' nullable metrics are not, and a curve needs one point per message.
The scenes are the Foxglove SDK's own messages and schema (:mod:`.scene`, :mod:`.sdk`).

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
curve point at the end of its last episode, a scene frame at the time of the state it
shows (scenes thus play at the control rate). Each channel's log times are non-decreasing.

Format versions (metadata ``format``; :mod:`.reader` reads both):

- ``a2cm_phys.episodes/1``: integer actions only; one step = 1 s.
- ``a2cm_phys.episodes/2``: continuous commands as float actions; ``dt`` and the clock
  follow the control period; a learned evader's reward and return (``evader_reward``,
  ``evader_return``); sparse update metrics (``exploit_*``) documented. Since added, in
  sensing scenarios only (SPEC §6b): the sensing masks of every state (``sensed``, see
  :data:`SENSED_FIELD` and :mod:`.masks`); their trajectory schema is
  :func:`trajectory_schema`'s, with the field; other logs are as before, byte for byte.
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
PLOT_EPISODES_TOPIC = "/plot/episodes"
"""The learning curve: a point per :data:`PLOT_EVERY` episodes (:data:`EPISODE_POINT_SCHEMA`)."""
PLOT_UPDATE_TOPIC = "/plot/update"
"""Each update's metrics as plain numbers (:data:`UPDATE_POINT_SCHEMA`)."""
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
"""Schema of :data:`TRAJECTORY_TOPIC` messages (without sensing; see :func:`trajectory_schema`)."""

SENSED_FIELD: dict[str, Any] = _rows(
    "integer",
    "sensing scenarios only; state rows: what each agent knows in that state (SPEC 6b), "
    "N + 1 integers, the pursuers in order then the evader: bit j (value 2^j) of agent i's "
    "integer is set when agent i knows body j (bodies: pursuers 0..N-1, then the evader N; "
    "its own bit is always set), as envs.sensing.sensed() gives it from the row's positions",
)
"""The ``sensed`` field of a sensing scenario's trajectory blocks (:mod:`.masks`)."""

HEADINGS_FIELD: dict[str, Any] = _rows(
    "number", "differential drive only; state rows: the pursuers' cos θ0,sin θ0,…"
)
"""The ``headings`` field of a differential-drive scenario's trajectory blocks."""


def trajectory_schema(scenario: Scenario) -> dict[str, Any]:
    """The trajectory schema of ``scenario``'s log: :data:`TRAJECTORY_SCHEMA`, with the
    ``sensed`` field (required) when the scenario has sensing and ``headings`` with
    differential drive; other logs keep the schema's bytes of before these fields."""
    if not scenario.sensing.on and not scenario.differential:
        return TRAJECTORY_SCHEMA
    schema = {**TRAJECTORY_SCHEMA, "properties": dict(TRAJECTORY_SCHEMA["properties"])}
    if scenario.differential:
        schema["properties"]["headings"] = HEADINGS_FIELD
    if scenario.sensing.on:
        schema["required"] = [*TRAJECTORY_SCHEMA["required"], "sensed"]
        schema["properties"]["sensed"] = SENSED_FIELD
    return schema


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


# --------------------------------------------------------------------------- plots

PLOT_EVERY = 5
"""Episodes averaged in each :data:`PLOT_EPISODES_TOPIC` point: the fewest whose points
cost the main job at most 5% of its time and 25% of its log (measured: about 1% and 18%;
every 10 episodes: 1% and 9%, every episode: 51% of the log; ``BENCHMARKS.md``)."""


def _numbers(fields: dict[str, str], kind: str = "number") -> dict[str, Any]:
    return {k: {"type": kind, "description": doc} for k, doc in fields.items()}


EPISODE_POINT_SCHEMA: dict[str, Any] = {
    "title": "a2cm_phys.EpisodePoint",
    "description": "A point of the learning curve: the means over the episodes with ids "
    "episode - episodes + 1 … episode (PLOT_EVERY of them; fewer at a part's start and end). "
    "Plain numbers only, so that Foxglove's Plot panel reads them.",
    "type": "object",
    "properties": {
        **_numbers(
            {
                "episode": "the point's last episode (ids in order of finishing)",
                "episodes": "episodes averaged",
            },
            "integer",
        ),
        **_numbers(
            {
                "length": "mean steps",
                "capture_steps": "mean steps of the captured episodes (absent if none was)",
                "return": "mean return (the pursuers' raw team reward summed)",
                "return_time": "mean of the return's time part (step, capture, wall terms)",
                "return_collision": "mean of the return's collision part",
                "evader_return": "learned evader only: its mean return",
                "captured": "fraction ended by a capture",
                "collision_terminated": "fraction ended by a collision",
                "truncated": "fraction that reached max_steps",
                "collisions": "mean pursuer collisions per episode",
                "wall_contacts": "mean wall contacts per episode",
            }
        ),
    },
    "required": [
        "episode",
        "episodes",
        "length",
        "return",
        "return_time",
        "return_collision",
        "captured",
        "collision_terminated",
        "truncated",
        "collisions",
        "wall_contacts",
    ],
}
"""Schema of :data:`PLOT_EPISODES_TOPIC` messages."""

UPDATE_POINT_SCHEMA: dict[str, Any] = {
    "title": "a2cm_phys.UpdatePoint",
    "description": "One learner update as plain numbers for Foxglove's Plot panel: the "
    "counters and the finite metrics of the /train/update message of the same update "
    "(a non-finite or non-numeric metric is left out).",
    "type": "object",
    "properties": {
        **_numbers(
            {
                "update": "the update",
                "env_steps": "environment steps so far (all games)",
                "episodes": "episodes finished so far",
            },
            "integer",
        ),
        **_numbers({k: k.replace("_", " ") for k in UPDATE_METRICS}),
        **_numbers(SPARSE_METRICS),
    },
    "additionalProperties": {"type": "number"},
    "required": ["update", "env_steps", "episodes"],
}
"""Schema of :data:`PLOT_UPDATE_TOPIC` messages."""

SCHEMAS: dict[str, dict[str, Any]] = {
    TRAJECTORY_TOPIC: TRAJECTORY_SCHEMA,
    SUMMARY_TOPIC: SUMMARY_SCHEMA,
    UPDATE_TOPIC: UPDATE_SCHEMA,
    PLOT_EPISODES_TOPIC: EPISODE_POINT_SCHEMA,
    PLOT_UPDATE_TOPIC: UPDATE_POINT_SCHEMA,
}
"""Schema of each fixed topic (JSON; the scene topics hold the Foxglove SDK's protobuf
``foxglove.SceneUpdate``, see :mod:`.sdk`); a sensing scenario's log: :func:`schemas_for`."""


def schemas_for(scenario: Scenario) -> dict[str, dict[str, Any]]:
    """The fixed topics' schemas in ``scenario``'s log: :data:`SCHEMAS`, with
    :func:`trajectory_schema` for the trajectories."""
    return {**SCHEMAS, TRAJECTORY_TOPIC: trajectory_schema(scenario)}


def schema_bytes(schema: dict[str, Any]) -> bytes:
    """The schema as stored in the MCAP Schema record (compact JSON)."""
    return json.dumps(schema, separators=(",", ":")).encode()
