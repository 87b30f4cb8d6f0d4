"""``policy.json``: everything a user needs to feed an exported actor and read its output
(the format is :mod:`a2cm_phys.deploy.spec`'s)."""

from __future__ import annotations

from typing import Any

from ...base.versions import __version__
from ...config import Scenario, to_dict
from ...deploy.spec import ACTION_MEANINGS, FORMAT, INPUT, LOG_STD, LOGITS, MEAN
from .graph import BATCH, IR_VERSION, OPSET


def observation_section(scenario: Scenario, encoding: str) -> dict[str, Any]:
    """What an actor's input holds, entry by entry, and how it is scaled and encoded."""
    agents = [*scenario.agents, "evader"]
    if scenario.mode == "grid":
        layout = [f"{a}.{c}" for a in agents for c in "xy"]
        divided_by = [float(scenario.size - 1)] * len(layout)
        units = ["cell"] * len(layout)
        scaling = (
            f"each agent's cell (x, y), 0 … {scenario.size - 1}, divided by size - 1 ="
            f" {scenario.size - 1}: values in [0, 1]"
        )
    else:
        speed = scenario.physics.max_speed
        layout = [f"{a}.{c}" for a in agents for c in "xy"]
        layout += [f"{a}.v{c}" for a in agents for c in "xy"]
        half = len(layout) // 2
        divided_by = [float(scenario.size)] * half + [float(speed)] * half
        units = ["m"] * half + ["m/s"] * half
        scaling = (
            f"every agent's centre (x, y) in metres divided by size = {scenario.size}, then"
            f" every agent's velocity (vx, vy) in m/s divided by max_speed = {speed:g}"
        )
        if scenario.differential:
            headings = [f"{a}.{c}" for a in scenario.agents for c in ("cos", "sin")]
            layout += headings
            divided_by += [1.0] * len(headings)
            units += ["1"] * len(headings)
            scaling += ", then every pursuer's heading θ as (cos θ, sin θ)"
    if encoding == "onehot":
        encoded = {
            "kind": "onehot",
            "cells": scenario.size,
            "rule": "inside the graph: each entry x becomes a one-hot vector of size cells at"
            " clip(round(x * (size - 1)), 0, size - 1) (round half to even)",
        }
    elif encoding == "relative":
        encoded = {
            "kind": "relative",
            "rule": "none in the graph: trained on each actor's view from its own body (the"
            " others' positions minus its own), a linear map folded into its first layer",
        }
    elif encoding == "metric":
        unit = "m" if scenario.mode == "physics" else "cells"
        encoded = {
            "kind": "metric",
            "scale": scenario.position_unit,
            "rule": "none in the graph: trained on each actor's view from its own body (the"
            f" others' positions minus its own, times scale: in {unit} on this arena), a"
            " linear map folded into its first layer; the actors play this arena size only",
        }
    else:
        encoded = {"kind": "xy", "rule": "none: the network reads the observation itself"}
    return {
        "tensor": INPUT,
        "size": scenario.obs_dim,
        "dtype": "float32",
        "layout": layout,
        "divided_by": divided_by,
        "units": units,
        "normalisation": f"done by the env, which gives {scaling}; feed the env's"
        " observation as it is (every agent receives the same global observation)",
        "encoding": encoded,
    }


def actions_section(scenario: Scenario) -> dict[str, Any]:
    """What an actor's output means and how it becomes the action the env plays."""
    if scenario.differential and scenario.continuous:
        return {
            "control": "continuous",
            "drive": "differential",
            "shape": [2],
            "dtype": "float32",
            "meaning": "(forward, turn): a pursuer's forward speed as a fraction of max_speed"
            " and its turn rate as a fraction of max_turn_rate (counter-clockwise positive),"
            " held for physics.dt seconds (one env step); the env clips each to [-1, 1]",
            "max_speed": scenario.physics.max_speed,
            "max_turn_rate": scenario.physics.max_turn_rate,
            "dt": scenario.physics.dt,
            "outputs": {MEAN: "the Gaussian's mean", LOG_STD: "its log standard deviation"},
        }
    if scenario.continuous:
        return {
            "control": "continuous",
            "shape": [2],
            "dtype": "float32",
            "meaning": "(vx, vy): a velocity command as a fraction of max_speed, held for"
            " physics.dt seconds (one env step); the env scales a command longer than 1"
            " back onto the unit circle: v / max(1, |v|)",
            "max_speed": scenario.physics.max_speed,
            "dt": scenario.physics.dt,
            "outputs": {MEAN: "the Gaussian's mean", LOG_STD: "its log standard deviation"},
        }
    moves = list(ACTION_MEANINGS[: scenario.actions])
    effect = (
        "one cell in that direction (a move into the wall stays put)"
        if scenario.mode == "grid"
        else f"max_speed = {scenario.physics.max_speed:g} m/s in that direction for"
        f" physics.dt = {scenario.physics.dt:g} s"
    )
    if scenario.differential:
        effect = (
            "the pursuer turns towards that direction at up to max_turn_rate, and drives"
            f" at max_speed = {scenario.physics.max_speed:g} m/s once it faces it, for"
            f" physics.dt = {scenario.physics.dt:g} s"
        )
    drive = {"drive": "differential"} if scenario.differential else {}
    return {
        "control": "discrete",
        **drive,
        "count": scenario.actions,
        "dtype": "int64",
        "meanings": moves,
        "meaning": f"the index of a move: {effect}",
        "outputs": {LOGITS: "unnormalised log-probabilities of the moves (softmax)"},
    }


def rules(scenario: Scenario) -> tuple[str, str]:
    """The greedy rule and the sampling rule, as sentences."""
    if scenario.continuous and scenario.differential:
        return (
            "the mean, each of (forward, turn) clipped to [-1, 1] (the command the env plays"
            " for the mean)",
            "mean + exp(log_std) * e, e standard normal per dimension, then each clipped to"
            " [-1, 1]",
        )
    if scenario.continuous:
        return (
            "the mean, scaled back onto the unit circle when longer than 1: mean / max(1,"
            " |mean|) (the command the env plays for the mean)",
            "mean + exp(log_std) * e, e standard normal per dimension, then scaled back onto"
            " the unit circle when longer than 1",
        )
    return (
        "argmax of the logits",
        "a sample of softmax(logits) (e.g. argmax of logits + Gumbel noise)",
    )


def onnx_section(scenario: Scenario) -> dict[str, Any]:
    """The graphs' opset and tensors."""
    n = 2 if scenario.continuous else scenario.actions
    heads = [MEAN, LOG_STD] if scenario.continuous else [LOGITS]
    return {
        "opset": OPSET,
        "ir_version": IR_VERSION,
        "input": {"name": INPUT, "shape": [BATCH, scenario.obs_dim], "dtype": "float32"},
        "outputs": [{"name": h, "shape": [BATCH, n], "dtype": "float32"} for h in heads],
        "batch_axis": f"dynamic ({BATCH!r}): any number of observations at once",
    }


def policy_document(
    scenario: Scenario,
    train: dict[str, Any],
    run: dict[str, Any],
    actors: list[dict[str, Any]],
) -> dict[str, Any]:
    """The whole ``policy.json``: ``run`` says where the actors come from, ``actors`` lists
    ``{"agent", "file", "sha256"}``."""
    greedy, sampling = rules(scenario)
    network = {k: train.get(k) for k in ("algo", "hidden", "layers", "encoding")}
    return {
        "format": FORMAT,
        "package_version": __version__,
        "run": run,
        "scenario": to_dict(scenario),
        "network": network,
        "observation": observation_section(scenario, str(train.get("encoding", "xy"))),
        "actions": actions_section(scenario),
        "greedy": greedy,
        "sampling": sampling,
        "onnx": onnx_section(scenario),
        "actors": actors,
    }
