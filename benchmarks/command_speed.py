"""How fast a trained continuous team's greedy commands are, and what full speed would buy.

    python benchmarks/command_speed.py RUN_DIR [--episodes 2000] [--seed 12345]

A Gaussian actor's greedy command is its mean; the env scales a command longer than 1 back
onto the unit circle and keeps a shorter one as it is, so a mean inside the circle is a
pursuer driving below ``max_speed``. The script plays the run's greedy team, prints the
share of commands shorter than 0.95 by the pursuer's distance to the evader and by its rank
(0: the nearest pursuer), then plays the same games with every command scaled onto the unit
circle (the same directions at full speed) and `pursuit` beside them. A team whose
full-speed twin is much faster is losing time to short commands near the evader, where an
actor's output, a continuous function of the offset, must turn fast (``BENCHMARKS.md``, "the
soft bound on the means"). Last, the phases of a game: the team and `pursuit` play the same
``--starts`` starts once each (no restarts), and the script prints the mean steps until the
nearest pursuer first comes within 3, 1.5 and 1 m of the evader (centre to centre) and the
steps from there to the end: where in a game the team loses its time.
"""

from __future__ import annotations

import argparse

import numpy as np
import torch

from a2cm_phys.analysis.evaluation import play
from a2cm_phys.analysis.policies import positions_from_obs, pursuit_policy
from a2cm_phys.envs.physics import PhysicsCore
from a2cm_phys.envs.vector import VectorEnv
from a2cm_phys.training.runs import load_trained_run, model_policy

BANDS = ((0.0, 0.8), (0.8, 1.5), (1.5, 2.5), (2.5, np.inf))  # metres, centre to centre
PHASES = (3.0, 1.5, 1.0)  # metres, centre to centre


def phases(scenario, policy, starts: int, seed: int) -> tuple[float, list[float]]:
    """Mean steps of ``starts`` games from seeded starts, played once each, and the mean
    step at which the nearest pursuer first comes within each of :data:`PHASES` metres of
    the evader (a game's length if it never does)."""
    seeds = np.random.default_rng(seed).integers(0, 2**63, starts).astype(np.uint64)
    core, rng = PhysicsCore(scenario, starts), np.random.default_rng(seed)
    core.reset(np.arange(starts), seeds)
    length, first = np.zeros(starts, int), np.full((len(PHASES), starts), -1)
    done, t = np.zeros(starts, bool), 0
    while not done.all():
        pos = core.positions()
        near = np.linalg.norm(pos[:, :-1] - pos[:, -1:], axis=-1).min(1)
        for k, radius in enumerate(PHASES):
            first[k, (first[k] < 0) & (near < radius) & ~done] = t
        out = core.step(np.asarray(policy(core.observe(), rng)))
        t += 1
        ended = (out.terminated | out.truncated) & ~done
        length[ended], done = t, done | ended
    first = np.where(first < 0, length, first)
    return float(length.mean()), [float(f.mean()) for f in first]


def main() -> None:
    """Print the greedy commands' speeds and the three teams' capture steps."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("run", help="a run directory of a continuous physics scenario")
    p.add_argument("--episodes", type=int, default=2000)
    p.add_argument("--seed", type=int, default=12345)
    p.add_argument("--starts", type=int, default=500, help="games of the phase split")
    args = p.parse_args()
    torch.set_num_threads(1)
    run = load_trained_run(args.run)
    scenario, greedy = run.scenario, model_policy(run.pursuers, True)

    env, rng = VectorEnv(scenario, 16), np.random.default_rng(args.seed)
    obs, lengths, dists, ranks = env.reset(args.seed), [], [], []
    for _ in range(3000):
        actions = np.asarray(greedy(obs, rng))
        pos = positions_from_obs(scenario, obs)  # (B, N + 1, 2)
        d = np.linalg.norm(pos[:, :-1] - pos[:, -1:], axis=-1)  # (B, N)
        lengths.append(np.linalg.norm(actions, axis=-1).ravel())
        dists.append(d.ravel())
        ranks.append(d.argsort(1).argsort(1).ravel())
        obs = env.step(actions, validate=False).obs
    env.close()
    short = np.concatenate(lengths) < 0.95
    dist, rank = np.concatenate(dists), np.concatenate(ranks)
    print(f"greedy commands shorter than 0.95: {short.mean():.3f} of {short.size}")
    for r in range(scenario.pursuers):
        print(f"  rank {r} (0: nearest the evader): {short[rank == r].mean():.3f}")
    for lo, hi in BANDS:
        band = (dist >= lo) & (dist < hi)
        print(f"  {lo}-{hi} m from the evader: {short[band].mean():.3f} of {band.sum()}")

    def full_speed(o: np.ndarray, g: np.random.Generator) -> np.ndarray:
        a = np.asarray(greedy(o, g), dtype=np.float64)
        return a / np.maximum(np.linalg.norm(a, axis=-1, keepdims=True), 1e-9)

    teams = {"greedy": greedy, "full speed": full_speed, "pursuit": pursuit_policy(scenario)}
    steps = {
        name: play(scenario, team, args.episodes, seed=args.seed).lengths.mean()
        for name, team in teams.items()
    }
    for name, value in steps.items():
        print(f"{name}: {value:.3f} steps, {value / steps['pursuit']:.4f}x pursuit")
    print(f"phases over {args.starts} starts (steps until the nearest pursuer is within):")
    for name in ("greedy", "pursuit"):
        length, first = phases(scenario, teams[name], args.starts, args.seed)
        within = ", ".join(f"{r:g} m {f:.2f}" for r, f in zip(PHASES, first, strict=True))
        print(f"  {name}: {within}; from {PHASES[-1]:g} m to the end {length - first[-1]:.2f}")


if __name__ == "__main__":
    main()
