"""The episodes a vector step finishes, column by column (:class:`EpisodeBatch`): read one by
one they are the per-episode summaries, with Python's own types; the trainer's tallies
read the columns and count what the per-episode loop counted."""

from __future__ import annotations

import math

import numpy as np

from a2cm_phys.config import load_scenario
from a2cm_phys.envs.tallies import EpisodeBatch, EpisodeSummary
from a2cm_phys.envs.vector import VectorEnv
from a2cm_phys.training.episode_stats import EpisodeStats


def _steps(scenario: str, envs: int = 6, steps: int = 200, seed: int = 0) -> list[EpisodeBatch]:
    sc = load_scenario(scenario)
    env = VectorEnv(sc, envs)
    env.reset(seed)
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(steps):
        actions = rng.integers(0, sc.actions, size=(envs, sc.pursuers))
        evader = rng.integers(0, sc.actions, size=envs) if sc.evader == "learned" else None
        out.append(env.step(actions, evader).episodes)
    return out


def test_a_batch_reads_as_summaries_with_python_types() -> None:
    batches = _steps("grid_collision")
    eps = [e for b in batches for e in b]
    assert len(eps) == sum(len(b) for b in batches) > 50
    for e in eps:
        assert isinstance(e, EpisodeSummary)
        assert type(e.env) is int and type(e.seed) is int and type(e.length) is int
        assert type(e.ret) is float and type(e.collisions) is int
        assert type(e.captured) is bool and type(e.truncated) is bool
        assert e.evader_ret is None
        assert not (e.captured and e.collision_terminated)
    batch = next(b for b in batches if len(b) > 1)
    assert batch[0] == next(iter(batch)) and batch[-1] == list(batch)[-1]
    assert batch == list(batch) and batch == EpisodeBatch.concat([batch])
    assert batch != list(batch)[:-1] and EpisodeBatch.empty() == []
    assert [e.env for e in batch] == sorted(e.env for e in batch)  # in the games' order


def test_concat_keeps_the_order_and_every_column() -> None:
    batches = [b for b in _steps("grid_vs") if len(b)]
    whole = EpisodeBatch.concat(batches)
    assert list(whole) == [e for b in batches for e in b]
    assert all(type(e.evader_ret) is float for e in whole)
    assert len(EpisodeBatch.empty()) == 0 and list(EpisodeBatch.empty()) == []
    assert EpisodeBatch.empty(learned_evader=True).evader_ret is not None
    empty = EpisodeBatch.empty(learned_evader=True)
    assert list(EpisodeBatch.concat([empty, batches[0]])) == list(batches[0])


def _stats_one_by_one(episodes: list[EpisodeSummary], window: int) -> EpisodeStats:
    """What the tallies counted when they took episodes one at a time."""
    stats = EpisodeStats(window)
    for e in episodes:
        stats.episodes += 1
        stats.captures += e.captured
        stats.truncations += e.truncated
        stats.collision_ends += e.collision_terminated
        stats.collisions += e.collisions
        evader = math.nan if e.evader_ret is None else e.evader_ret
        stats.recent.append((e.length, e.ret, e.collisions, evader))
    return stats


def test_tallies_from_columns_equal_one_by_one() -> None:
    for scenario in ("grid_collision_continue", "grid_vs"):
        batches = _steps(scenario, steps=300)
        for window in (7, 1000):
            stats = EpisodeStats(window)
            for b in batches:
                stats.add(b)
            want = _stats_one_by_one([e for b in batches for e in b], window)
            got_state, want_state = stats.state(), want.state()
            np.testing.assert_array_equal(got_state.pop("recent"), want_state.pop("recent"))
            assert got_state == want_state and stats.collisions > 0
            assert [type(v) for v in stats.recent[-1]] == [type(v) for v in want.recent[-1]]
