"""The physics core's direct paths (``chipmunk.DIRECT_CALLS``): bodies read and steered through
chipmunk's memory, contacts reported by C callbacks in chipmunk's own handler. Each must give
exactly the trajectories of pymunk's API."""

import subprocess
import sys

import numpy as np
import pytest

from a2cm_phys.config import load_scenario
from a2cm_phys.envs import chipmunk
from a2cm_phys.envs.physics import PhysicsCore


def rollout(core: PhysicsCore, steps: int, seed: int) -> list:
    """Random commands or moves (half the games chase the evader, a quarter pile up in the
    middle), games reset when they end and at random, spares taken by some resets; per step
    the positions, velocities, observation and outcome."""
    sc, b, n = core.scenario, core.num_envs, core.scenario.pursuers
    rng = np.random.default_rng(seed)
    core.reset(np.arange(b), rng.integers(0, 2**63, b).astype(np.uint64))
    trace = []
    for k in range(steps):
        pos = core.positions()
        chase = pos[:, n : n + 1] - pos[:, :n]
        if sc.continuous:
            actions = rng.uniform(-1.5, 1.5, (b, n, 2))  # some outside the unit disc
            actions[::2] = chase[::2]
            actions[1::4] = 2.0 * (sc.size / 2 - pos[1::4, :n])
        else:
            actions = rng.integers(0, 5, (b, n))
            along_x = np.abs(chase[..., 0]) > np.abs(chase[..., 1])
            toward = np.where(
                along_x, np.where(chase[..., 0] > 0, 1, 2), np.where(chase[..., 1] > 0, 3, 4)
            )
            actions[::2] = toward[::2]
        out = core.step(actions)
        trace.append((core.positions(), core.velocities(), core.observe(), out))
        done = np.flatnonzero(out.terminated | out.truncated | (rng.random(b) < 0.03))
        if len(done):
            core.reset(done, rng.integers(0, 2**63, len(done)).astype(np.uint64))
        if k % 7 == 0:
            core.build_spare()
    return trace


def test_the_body_layout_is_known_to_this_chipmunk():
    """Else the direct path would silently fall back to per-body calls."""
    assert chipmunk.body_layout()


@pytest.mark.parametrize("name", ["phys_cont_collision", "phys_cont_flee", "phys_flee"])
def test_memory_access_and_c_callbacks_match_pymunks_api(name, monkeypatch):
    sc = load_scenario(name)
    fast = PhysicsCore(sc, 6)
    assert fast._worlds.addresses is not None
    assert all(world._hooked is not None for world in fast._worlds)
    ours = rollout(fast, 300, 3)
    assert fast.spare_worlds < 50
    monkeypatch.setattr(chipmunk, "DIRECT_CALLS", False)
    slow = PhysicsCore(sc, 6)
    assert slow._worlds.addresses is None
    assert all(world._hooked is None for world in slow._worlds)
    theirs = rollout(slow, 300, 3)
    events = 0
    for (pos_a, vel_a, obs_a, out_a), (pos_b, vel_b, obs_b, out_b) in zip(
        ours, theirs, strict=True
    ):
        np.testing.assert_array_equal(pos_a, pos_b)
        np.testing.assert_array_equal(vel_a, vel_b)
        np.testing.assert_array_equal(obs_a, obs_b)
        assert out_a.events == out_b.events
        for field in ("reward", "terminated", "truncated", "collisions", "evader_action"):
            np.testing.assert_array_equal(getattr(out_a, field), getattr(out_b, field))
        events += sum(len(game) for game in out_a.events)
    assert events > 30  # contacts, captures and collisions were exercised


def test_spare_worlds_move_the_memory_view():
    """A reset that takes a spare world re-maps the memory view to its bodies."""
    sc = load_scenario("phys_cont")
    core = PhysicsCore(sc, 2)
    for _ in range(3):
        core.build_spare()
    core.reset(np.array([1]), np.array([5], dtype=np.uint64))
    taken = core._worlds[1]
    np.testing.assert_array_equal(core._worlds.addresses[1], taken.addresses)
    core.step(np.full((2, sc.pursuers, 2), 0.5))
    read = core.positions()[1]
    np.testing.assert_array_equal(read, [tuple(body.position) for body in taken.bodies])


def test_freeing_worlds_in_contact_is_safe():
    """A space freed while its shapes touch calls its separate callback; the world's C
    callbacks are unhooked first (a crash here would kill the interpreter, so it runs in a
    child process)."""
    code = """
import gc
import numpy as np
from a2cm_phys.config import load_scenario
from a2cm_phys.envs.physics import PhysicsCore
sc = load_scenario("phys_cont_collision_continue")
for _ in range(5):
    core = PhysicsCore(sc, 4)
    for _ in range(40):  # everyone into the same corner: contacts everywhere
        core.step(np.full((4, sc.pursuers, 2), -1.0))
    del core
    gc.collect()
print("ok")
"""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "ok"
