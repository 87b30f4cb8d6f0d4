"""The paper's grid rules (SPEC §2, §4), case by case, written by hand."""

from __future__ import annotations

import numpy as np
import pytest

from a2cm_phys import make_env
from a2cm_phys.config import load_scenario
from a2cm_phys.envs.grid import GridCore

UP, DOWN, LEFT, RIGHT, STAY = 0, 1, 2, 3, 4


def play(positions, pursuer_actions, evader_action=STAY, scenario="grid", **overrides):
    """One step from explicit positions; returns (positions after, outcome)."""
    sc = load_scenario(scenario, {"evader": "static", **overrides})
    core = GridCore(sc, 1)
    names = [*sc.agents, "evader"]
    core.reset(
        np.array([0]), np.array([0], dtype=np.uint64), [dict(zip(names, positions, strict=True))]
    )
    new, captured, collisions, walls = core.rules.apply(
        core.cells, np.array([pursuer_actions]), np.array([evader_action])
    )
    xy = core.rules.cell_xy[new[:, 0]]
    return [tuple(int(v) for v in p) for p in xy], captured[0], int(collisions[0]), int(walls[0])


# (description, start positions p0 p1 p2 evader, pursuer actions, evader action,
#  expected positions, captured, collisions, wall bumps)
# fmt: off
CASES = [
    ("plain moves", [(1, 1), (3, 1), (1, 3), (4, 4)], [UP, LEFT, RIGHT], DOWN,
     [(1, 2), (2, 1), (2, 3), (4, 3)], False, 0, 0),
    ("capture: pursuer steps onto the evader", [(2, 1), (0, 0), (4, 0), (2, 2)], [UP, UP, UP], STAY,
     [(2, 2), (0, 1), (4, 1), (2, 2)], True, 0, 0),
    ("capture: evader steps onto a pursuer", [(2, 1), (0, 0), (4, 0), (2, 2)], [STAY, UP, UP],
     DOWN, [(2, 1), (0, 1), (4, 1), (2, 1)], True, 0, 0),
    ("capture: both move into the same cell", [(1, 2), (0, 0), (4, 0), (3, 2)], [RIGHT, UP, UP],
     LEFT, [(2, 2), (0, 1), (4, 1), (2, 2)], True, 0, 0),
    ("capture: pursuer and evader swap cells", [(2, 1), (0, 0), (4, 0), (2, 2)], [UP, UP, UP], DOWN,
     [(2, 2), (0, 1), (4, 1), (2, 1)], True, 0, 0),
    ("no capture: evader steps away as pursuer follows", [(2, 1), (0, 0), (4, 0), (2, 2)],
     [UP, UP, UP], UP, [(2, 2), (0, 1), (4, 1), (2, 3)], False, 0, 0),
    ("collision: two pursuers end on one cell", [(1, 1), (3, 1), (0, 4), (4, 4)],
     [RIGHT, LEFT, DOWN], STAY, [(2, 1), (2, 1), (0, 3), (4, 4)], False, 1, 0),
    ("collision: two pursuers swap cells", [(1, 1), (2, 1), (0, 4), (4, 4)], [RIGHT, LEFT, DOWN],
     STAY, [(2, 1), (1, 1), (0, 3), (4, 4)], False, 1, 0),
    ("collision: a pursuer walks onto one blocked by the wall", [(0, 0), (1, 0), (4, 4), (2, 2)],
     [LEFT, LEFT, DOWN], STAY, [(0, 0), (0, 0), (4, 3), (2, 2)], False, 1, 1),
    ("no collision: following in a line", [(0, 1), (1, 1), (2, 1), (4, 4)], [RIGHT, RIGHT, RIGHT],
     STAY, [(1, 1), (2, 1), (3, 1), (4, 4)], False, 0, 0),
    ("three pursuers on one cell = 3 pairs", [(1, 2), (3, 2), (2, 3), (4, 4)], [RIGHT, LEFT, DOWN],
     STAY, [(2, 2), (2, 2), (2, 2), (4, 4)], False, 3, 0),
    ("capture and collision in the same step", [(1, 2), (3, 2), (0, 0), (2, 2)],
     [RIGHT, LEFT, UP], STAY, [(2, 2), (2, 2), (0, 1), (2, 2)], True, 1, 0),
    ("swap and same-cell collisions together", [(1, 1), (2, 1), (3, 1), (4, 4)],
     [RIGHT, LEFT, LEFT], STAY, [(2, 1), (1, 1), (2, 1), (4, 4)], False, 2, 0),
]
# fmt: on


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_rule_case(case):
    _, start, acts, ev, expected, captured, collisions, walls = case
    got = play(start, acts, ev, actions=5)
    assert got == (expected, captured, collisions, walls)


CORNERS = {
    "bottom-left": ((0, 0), [DOWN, LEFT]),
    "bottom-right": ((4, 0), [DOWN, RIGHT]),
    "top-left": ((0, 4), [UP, LEFT]),
    "top-right": ((4, 4), [UP, RIGHT]),
}


@pytest.mark.parametrize("corner", CORNERS)
@pytest.mark.parametrize("action", [UP, DOWN, LEFT, RIGHT])
def test_clipping_in_every_corner_and_direction(corner, action):
    cell, blocked = CORNERS[corner]
    others = [(2, 1), (2, 3), (3, 2)]
    (p0, *_), _, _, walls = play([cell, *others[:2], others[2]], [action, STAY, STAY], actions=5)
    dx, dy = [(0, 1), (0, -1), (-1, 0), (1, 0)][action]
    if action in blocked:
        assert p0 == cell and walls == 1
    else:
        assert p0 == (cell[0] + dx, cell[1] + dy) and walls == 0


@pytest.mark.parametrize(
    ("cell", "action"), [((2, 0), DOWN), ((2, 4), UP), ((0, 2), LEFT), ((4, 2), RIGHT)]
)
def test_clipping_on_every_edge(cell, action):
    (p0, *_), _, _, walls = play([cell, (1, 1), (3, 3), (2, 2)], [action, STAY, STAY], actions=5)
    assert p0 == cell and walls == 1


def episode(scenario, positions, joint_actions, **overrides):
    """Run an env from positions with a static evader; returns the list of step results."""
    env = make_env(scenario, evader="static", **overrides)
    env.reset(seed=0, options={"positions": positions})
    steps = []
    for joint in joint_actions:
        _, rew, term, trunc, info = env.step(dict(zip(env.possible_agents, joint, strict=True)))
        steps.append((rew["pursuer_0"], term["pursuer_0"], trunc["pursuer_0"], info["pursuer_0"]))
        if not env.agents:
            break
    return steps


MEET = {"pursuer_0": (1, 1), "pursuer_1": (3, 1), "pursuer_2": (0, 4), "evader": (4, 4)}


def test_collision_mode_off_counts_but_does_not_penalise():
    (r, term, trunc, info), *_ = episode("grid", MEET, [(RIGHT, LEFT, DOWN)] * 2)
    assert info["collisions"] == 1 and r == -1.0 and not term and not trunc


def test_collision_mode_terminate_penalises_and_ends():
    steps = episode("grid_collision", MEET, [(RIGHT, LEFT, DOWN)] * 3)
    assert len(steps) == 1
    r, term, trunc, info = steps[0]
    assert r == -1000.0 - 150_000_000.0 and term and not trunc and not info["captured"]


def test_collision_mode_penalize_goes_on_and_penalises_each_overlapping_step():
    steps = episode("grid_collision_continue", MEET, [(RIGHT, LEFT, DOWN), (DOWN, DOWN, DOWN)])
    assert len(steps) == 2
    assert [s[0] for s in steps] == [-1000.0 - 150_000_000.0] * 2  # still on one cell
    assert not any(s[1] for s in steps)


def test_capture_reward_and_termination():
    steps = episode(
        "grid",
        {**MEET, "evader": (1, 2)},
        [(UP, STAY, STAY)],
        actions=5,
        **{"rewards.capture": 10.0},
    )
    assert steps == [(9.0, True, False, steps[0][3])] and steps[0][3]["captured"]


def test_wall_reward():
    ((r, *_),) = episode("grid", MEET, [(STAY, STAY, UP)], actions=5, **{"rewards.wall": -0.5})
    assert r == -1.5


@pytest.mark.parametrize("max_steps", [1, 3, 7])
def test_truncation_at_exactly_max_steps(max_steps):
    steps = episode("grid", MEET, [(UP, UP, DOWN), (DOWN, DOWN, UP)] * 10, max_steps=max_steps)
    assert len(steps) == max_steps
    assert [s[2] for s in steps] == [False] * (max_steps - 1) + [True]
    assert not any(s[1] for s in steps)  # truncation is never termination


def test_capture_on_the_last_step_is_termination_not_truncation():
    steps = episode("grid", {**MEET, "evader": (1, 2)}, [(UP, STAY, STAY)], actions=5, max_steps=1)
    assert steps[0][1] and not steps[0][2]


def test_observation_layout():
    env = make_env("grid")
    obs, _ = env.reset(seed=0)
    expected = np.array([0, 0, 4, 0, 0, 4, 2, 2], dtype=np.float32) / 4
    np.testing.assert_array_equal(obs["pursuer_0"], expected)
    np.testing.assert_array_equal(env.state(), expected)
    assert obs["pursuer_0"].dtype == np.float32


def test_default_start_places_extra_pursuers_on_the_border():
    env = make_env("grid", pursuers=6)
    env.reset(seed=0)
    cells = env.game.core.positions()[0]
    assert [tuple(c) for c in cells] == [(0, 0), (4, 0), (0, 4), (4, 4), (1, 0), (2, 0), (2, 2)]


def test_render_text_picture():
    env = make_env("grid")
    env.reset(seed=0, options={"positions": {"pursuer_1": (1, 0)}})
    assert env.render() == "2 . . . .\n. . . . .\n. . E . .\n. . . . .\n0 1 . . ."
