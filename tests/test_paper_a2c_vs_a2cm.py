"""A2C and A2CM under ``--preset paper`` are two algorithms, even where they play alike.

Issue 36 found a one-seed report in which they completed the same episodes on both collision
scenarios. That is the paper's reward scale, not one algorithm run twice: a collision costs
1.5e8, so while most batches hold one, every return is dominated by it, the critics' values
(a few units) vanish beside it in float32, and RMSprop normalises the actors' steps; both
take nearly the same steps (after 100 updates their actors differ by about 1e-4 of their
weights) and sample the same actions. Where the critics matter they part at once.
"""

from __future__ import annotations

import tempfile

from a2cm_phys.config import load_scenario, load_train, preset, resolve_train
from a2cm_phys.training.trainer import Trainer


def _trained(scenario: str, algo: str, updates: int) -> Trainer:
    sc = load_scenario(scenario)
    options = {**preset("paper"), "algo": algo, "seed": 0, "updates": updates}
    cfg = resolve_train(sc, load_train(options))
    with tempfile.TemporaryDirectory() as tmp:
        trainer = Trainer(sc, cfg, tmp, record=False, progress=False)
        assert trainer.run() == "done"
    return trainer


def _actor_gap(a: Trainer, b: Trainer) -> float:
    """The largest difference between the two teams' actor weights, relative to their size."""
    sa, sb = a.model.state_dict(), b.model.state_dict()
    keys = [k for k in sa if k.startswith("actor")]
    assert keys and all(sa[k].shape == sb[k].shape for k in keys)
    return max(float((sa[k] - sb[k]).abs().max() / sa[k].abs().max()) for k in keys)


def test_without_a_penalty_the_critics_tell_them_apart() -> None:
    a2c, a2cm = _trained("grid", "a2c", 40), _trained("grid", "a2cm", 40)
    critic = "critic_out.weight"
    assert a2c.model.state_dict()[critic].shape[0] == 3  # one critic per pursuer
    assert a2cm.model.state_dict()[critic].shape[0] == 1  # one shared critic
    assert _actor_gap(a2c, a2cm) > 1e-2
    assert a2c.stats.episodes != a2cm.stats.episodes


def test_under_the_collision_penalty_they_differ_but_little() -> None:
    a2c, a2cm = _trained("grid_collision", "a2c", 40), _trained("grid_collision", "a2cm", 40)
    gap = _actor_gap(a2c, a2cm)
    assert 0 < gap < 1e-2  # two learners, whose steps the 1.5e8 penalty makes alike
