"""Property tests of the physics core: no tunnelling, no blow-ups.

After every step of every game: all coordinates finite, every body's centre inside the
arena (a centre past a wall's inner edge means the body went through it), no two bodies
more than half into each other, and no agent faster than twice ``max_speed`` (the servos
drive to ``max_speed``; pushes add a sideways component, never a blow-up). Bodies do
overlap briefly on impact, by up to the distance they close in one substep (0.2 m at
full speed head-on with the default 10 substeps): that is the solver's resolution, not
tunnelling. Hypothesis draws action programs over every discrete phys scenario, and
programs of velocity commands over every continuous one; four adversarial batches (a
pile-up in a corner, head-on slams at full speed with moves and with velocity commands,
stiff servos) bring the total over 10⁵ steps. (Continuous scenarios close at most 0.1 m
per substep: 2 m/s over 0.05 s.)
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from a2cm_phys.config import load_scenario, scenario_names
from a2cm_phys.envs.physics import PhysicsCore

UP, DOWN, LEFT, RIGHT, STAY = range(5)
PHYS_ALL = [name for name in scenario_names() if name.startswith("phys")]
CONT = [name for name in PHYS_ALL if load_scenario(name).continuous]  # phys_diff* too
PHYS = [name for name in PHYS_ALL if name not in CONT]
ADVERSARIAL_GAMES, ADVERSARIAL_STEPS = 32, 1_100  # 4 batches: 140,800 steps


def check(core: PhysicsCore, overlaps: bool = True) -> None:
    """The invariants of the module docstring, for every game of ``core`` (the overlap bound
    only if ``overlaps``)."""
    sc, ph = core.scenario, core.scenario.physics
    pos, vel = core.positions(), core.velocities()
    assert np.isfinite(pos).all() and np.isfinite(vel).all()
    assert ((pos >= 0) & (pos <= sc.size)).all(), pos[~((pos >= 0) & (pos <= sc.size)).all((1, 2))]
    assert (np.linalg.norm(vel, axis=-1) <= 2 * ph.max_speed).all()
    assert (core.kinetic_energy() <= (sc.pursuers + 1) * 2 * ph.mass * ph.max_speed**2).all()
    n = sc.pursuers
    for i in range(n if overlaps else 0):  # box–box: overlap depth along the shallower axis
        for j in range(i + 1, n):
            gap = np.abs(pos[:, i] - pos[:, j]).max(axis=-1)
            assert (gap > ph.box_side / 2).all()
        centre_gap = np.linalg.norm(pos[:, i] - pos[:, n], axis=-1)
        assert (centre_gap > (ph.box_side / 2 + ph.evader_radius) / 2).all()


def run(core: PhysicsCore, actions: np.ndarray, seed: int, overlaps: bool = True) -> None:
    """Step ``actions`` ``(T, B, N)`` without restarting finished games, checking each step."""
    core.reset(
        np.arange(core.num_envs), np.arange(core.num_envs, dtype=np.uint64) + np.uint64(seed)
    )
    for acts in actions:
        core.step(acts)
        check(core, overlaps)


segments = st.lists(
    st.tuples(st.integers(1, 12), st.lists(st.integers(0, 4), min_size=3, max_size=3)),
    min_size=1,
    max_size=10,
)


@settings(max_examples=30, deadline=None)
@given(
    name=st.sampled_from(PHYS),
    evader=st.sampled_from(["random", "flee", "static"]),
    n_actions=st.sampled_from([4, 5]),
    program=segments,
    seed=st.integers(0, 2**32),
)
def test_action_programs_keep_the_world_sound(name, evader, n_actions, program, seed):
    """Each game plays the drawn program with its actions rotated by the game's index."""
    sc = load_scenario(name, {"evader": evader, "actions": n_actions})
    batch = 12
    rows = [np.array(acts) for length, acts in program for _ in range(length)]
    base = np.stack(rows)[:, None, : sc.pursuers]  # (T, 1, N)
    actions = (base + np.arange(batch)[None, :, None]) % n_actions
    run(PhysicsCore(sc, batch), actions, seed)


command_segments = st.lists(
    st.tuples(
        st.integers(1, 40),  # steps (0.1 s each)
        st.lists(  # per pursuer: heading (turns) and length, up to past the unit disc
            st.tuples(st.floats(0, 1), st.floats(0, 1.5)), min_size=3, max_size=3
        ),
    ),
    min_size=1,
    max_size=10,
)


@settings(max_examples=30, deadline=None)
@given(
    name=st.sampled_from(CONT),
    evader=st.sampled_from(["random", "flee", "static"]),
    program=command_segments,
    seed=st.integers(0, 2**32),
)
def test_command_programs_keep_the_world_sound(name, evader, program, seed):
    """Each game plays the drawn program of velocity commands turned by ``g / batch`` of a
    turn, ``g`` the game's index."""
    sc = load_scenario(name, {"evader": evader})
    batch = 12
    rows = [np.array(cmds) for length, cmds in program for _ in range(length)]
    turns, length = np.stack(rows)[..., 0], np.stack(rows)[..., 1]  # (T, N)
    angle = 2 * np.pi * (turns[:, None] + np.arange(batch)[None, :, None] / batch)
    actions = length[:, None, :, None] * np.stack((np.cos(angle), np.sin(angle)), axis=-1)
    run(PhysicsCore(sc, batch), actions, seed)


@pytest.mark.slow
def test_pile_up_in_a_corner():
    """Everyone (the fleeing evader too, when cornered) pushes into one corner per game."""
    sc = load_scenario("phys_flee")
    corner = np.arange(ADVERSARIAL_GAMES) % 4  # game g piles into corner g % 4
    horizontal = np.where(corner % 2 == 0, LEFT, RIGHT)
    vertical = np.where(corner < 2, DOWN, UP)
    steps = np.arange(ADVERSARIAL_STEPS)[:, None]
    toward = np.where(steps % 2 == 0, horizontal[None], vertical[None])  # (T, B): zig-zag
    actions = np.repeat(toward[..., None], sc.pursuers, axis=2)
    run(PhysicsCore(sc, ADVERSARIAL_GAMES), actions, 11)


@pytest.mark.slow
def test_head_on_slams_at_full_speed():
    """Pursuers 0 and 1 charge each other and back off, 2 charges the evader; game g turns
    around every g % 6 + 1 steps, so slams happen at every phase of a step."""
    sc = load_scenario("phys_collision_continue", {"evader": "random"})
    period = np.arange(ADVERSARIAL_GAMES) % 6 + 1
    phase = (np.arange(ADVERSARIAL_STEPS)[:, None] // period[None]) % 2  # (T, B)
    actions = np.stack(
        [
            np.where(phase == 0, RIGHT, LEFT),
            np.where(phase == 0, LEFT, RIGHT),
            np.where(phase == 0, UP, DOWN),
        ],
        axis=-1,
    )
    run(PhysicsCore(sc, ADVERSARIAL_GAMES), actions, 22)


@pytest.mark.slow
def test_continuous_slams_and_random_commands():
    """Continuous control: pursuers 0 and 1 charge each other and back off at full speed
    (game g turns around every g % 12 + 1 control steps), 2 takes random commands, some
    far outside the unit disc."""
    sc = load_scenario("phys_cont_collision_continue", {"evader": "flee"})
    period = np.arange(ADVERSARIAL_GAMES) % 12 + 1
    sign = 1.0 - 2.0 * ((np.arange(ADVERSARIAL_STEPS)[:, None] // period[None]) % 2)  # (T, B)
    rng = np.random.default_rng(44)
    actions = np.zeros((ADVERSARIAL_STEPS, ADVERSARIAL_GAMES, sc.pursuers, 2))
    actions[:, :, 0, 0], actions[:, :, 1, 0] = sign, -sign
    actions[:, :, 2] = rng.uniform(-3, 3, (ADVERSARIAL_STEPS, ADVERSARIAL_GAMES, 2))
    run(PhysicsCore(sc, ADVERSARIAL_GAMES), actions, 55)


@pytest.mark.slow
def test_stiff_servos_with_random_play():
    """Ten times the servo force: still no tunnelling through walls and no blow-up. (Bodies
    squeezed by such servos overlap deeper, the contact solver trading penetration against
    the servos' impulses; the overlap bound is for the shipped servo force.)"""
    sc = load_scenario("phys", {"physics.max_force": 10 * load_scenario("phys").physics.max_force})
    rng = np.random.default_rng(5)
    actions = rng.integers(0, sc.actions, (ADVERSARIAL_STEPS, ADVERSARIAL_GAMES, sc.pursuers))
    run(PhysicsCore(sc, ADVERSARIAL_GAMES), actions, 33, overlaps=False)
