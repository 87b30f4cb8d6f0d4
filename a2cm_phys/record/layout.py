"""The Foxglove layout of a run (``docs/foxglove/layout.json``), built with the Foxglove
SDK's layout types (:mod:`foxglove.layouts`).

A 3D panel on the arena (frame ``arena``, seen from above at an angle) showing the scenes:
the live view's and ``replay --serve``'s ``/scene``, and a log's ``/scene/env_<i>``; beside
it, plots of the learning curve against the episode (``/plot/episodes``): capture steps and
episode length, the return and its two parts, collisions and the share of episodes a
collision ended; and of the learner against the update (``/plot/update``). The plots use
the episode and update numbers as their x-axis, so they read the same in a log and live.
"""

from __future__ import annotations

import json
from typing import Any

from .schemas import PLOT_EPISODES_TOPIC, PLOT_UPDATE_TOPIC, SCENE_TOPIC_PREFIX

SCENE_TOPICS = ("/scene", *(f"{SCENE_TOPIC_PREFIX}{i}" for i in range(16)))
"""The scene topics the 3D panel shows: the live and served one, a log's first 16 games."""
ARENA_CENTRE = 2.5
"""Where the camera looks (metres, both axes): the centre of the default 5 × 5 arena."""


def _plot(title: str, topic: str, x: str, series: dict[str, str], y_label: str) -> Any:
    """A Plot panel of ``topic``'s fields ``series`` (field: label) against field ``x``."""
    import foxglove.layouts as fl

    return fl.PlotPanel(
        title=title,
        config=fl.PlotConfig(
            paths=[
                fl.PlotSeries(value=f"{topic}.{field}", label=label, show_line=True)
                for field, label in series.items()
            ],
            x_axis_val="custom",
            x_axis_path=fl.PlotXAxisPath(value=f"{topic}.{x}"),
            x_axis_label=x,
            y_axis_label=y_label,
            show_legend=True,
            legend_display="top",
        ),
    )


def foxglove_layout() -> str:
    """The layout as Foxglove's layout JSON (indented; the file in ``docs/foxglove``)."""
    import foxglove.layouts as fl

    ep, up = PLOT_EPISODES_TOPIC, PLOT_UPDATE_TOPIC
    scene = fl.ThreeDeePanel(
        title="arena",
        config=fl.ThreeDeeConfig(
            follow_tf="arena",
            camera_state=fl.ThreeDeeCameraState(
                target_offset=(ARENA_CENTRE, ARENA_CENTRE, 0.0),
                distance=9.0,
                phi=30.0,
                theta_offset=0.0,
                perspective=True,
            ),
            topics={t: fl.BaseRendererSceneUpdateTopicSettings(visible=True) for t in SCENE_TOPICS},
        ),
    )
    plots = [
        _plot(
            "capture steps",
            ep,
            "episode",
            {"capture_steps": "capture steps (captured episodes)", "length": "episode length"},
            "steps",
        ),
        _plot(
            "return",
            ep,
            "episode",
            {"return": "return", "return_time": "time part", "return_collision": "collision part"},
            "return",
        ),
        _plot(
            "collisions",
            ep,
            "episode",
            {
                "collisions": "collisions per episode",
                "collision_terminated": "ended by a collision",
                "captured": "captured",
            },
            "per episode",
        ),
        _plot(
            "learner",
            up,
            "update",
            {"policy_loss": "policy loss", "value_loss": "value loss", "entropy": "entropy"},
            "loss",
        ),
    ]
    column = fl.SplitContainer(
        direction="column", items=[fl.SplitItem(proportion=1, content=p) for p in plots]
    )
    layout = fl.Layout(
        content=fl.SplitContainer(
            direction="row",
            items=[
                fl.SplitItem(proportion=3, content=scene),
                fl.SplitItem(proportion=2, content=column),
            ],
        )
    )
    return json.dumps(json.loads(layout.to_json()), indent=2) + "\n"
