"""A hash of what training computes, to prove a refactor bit-identical (run it on both sides).

    PYTHONPATH=CHECKOUT python benchmarks/learner_hash.py LABEL

Trains six short runs (grid and physics, A2C and A2CM, continuous control, self-play; seed
3, no log) and hashes every weight of every team and the optimiser's state. The entropy is
pinned to the values the defaults had before the entropy schedule (1e-4 constant; 0.03 in
self-play), the games, batch and step size to 16, 128 and 7e-3 (the defaults everywhere
until issue 35's wider grid batches), the continuous run's cell-area shaping and gradient
clipping to off (as before they existed) and its initial log-std to −0.5 (its default
until 2026-12-02), so checkouts from before and after them compare. Equal hashes: the same floats.
"""

from __future__ import annotations

import dataclasses
import hashlib
import sys
import tempfile

import torch

from a2cm_phys.config import Train, load_scenario, load_train, resolve_train
from a2cm_phys.training.trainer import Trainer

RUNS = (
    ("grid_collision", "a2cm", 200),
    ("grid_collision", "a2c", 50),
    ("phys_collision", "a2cm", 30),
    ("grid", "a2cm", 30),
    ("phys_cont", "a2cm", 30),
    ("grid_vs", "a2cm", 50),
)


def options(name: str, updates: int, algo: str) -> dict:
    """The run's training options, the entropy pinned (and its schedule, where it exists)."""
    out = {"updates": updates, "seed": 3, "algo": algo}
    out.update(num_envs=16, batch_size=128, lr=7e-3)
    out["entropy_coef"] = 0.03 if name == "grid_vs" else 1e-4
    fields = {f.name for f in dataclasses.fields(Train)}
    if "entropy_schedule" in fields:
        out["entropy_schedule"] = "constant"
    out["max_grad_norm"] = 0.0
    if "area_shaping" in fields:
        out["area_shaping"] = 0.0
    if name.startswith("phys_cont"):  # the continuous default before 2026-12-02
        out["log_std_init"] = -0.5
    return out


def main() -> None:
    """Print ``LABEL HASH``."""
    torch.set_num_threads(1)
    digest = hashlib.sha256()
    with tempfile.TemporaryDirectory() as tmp:
        for name, algo, updates in RUNS:
            scenario = load_scenario(name)
            cfg = resolve_train(scenario, load_train(options(name, updates, algo)))
            trainer = Trainer(scenario, cfg, f"{tmp}/{name}-{algo}", record=False)
            trainer.run()
            for key, value in sorted(trainer.model.state_dict().items()):
                digest.update(key.encode())
                digest.update(value.numpy().tobytes())
            optimiser = trainer.checkpoint_state()["learner"]["optimizer"]["state"]
            for _, entry in sorted(optimiser.items()):
                for _, value in sorted(entry.items()):
                    digest.update(torch.as_tensor(value).numpy().tobytes())
            if trainer.evader is not None:
                for key, value in sorted(trainer.evader.model.state_dict().items()):
                    digest.update(key.encode())
                    digest.update(value.numpy().tobytes())
    print(sys.argv[1] if len(sys.argv) > 1 else "", digest.hexdigest()[:16])


if __name__ == "__main__":
    main()
