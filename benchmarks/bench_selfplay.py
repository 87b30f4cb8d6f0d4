"""Self-play on the grid, measured exactly (issue 14).

    python benchmarks/bench_selfplay.py --seeds 0-4 [--updates 5000] [--jobs 2]

For each seed: A2CM pursuers trained against the random evader on ``grid`` (640,000 steps,
the defaults) and A2CM pursuers + an A2C evader trained by self-play on ``grid_vs``. Then,
exactly, by dynamic programming over the joint states (``a2cm_phys.solve``), the expected
capture time E[min(T, 1000)] from the default start of every pairing of
{random-trained, self-play, oracle} pursuers × {random, flee, learned, best-response}
evaders; the learned evader is the self-play run's of the same seed. The oracle is the team
that is optimal against the random evader. Also the training throughput of self-play
against single-team training on the same scenario with a scripted evader.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor

PURSUERS = ("random-trained", "self-play", "oracle")
EVADERS = ("random", "flee", "learned", "best-response")


def train(scenario: str, seed: int, updates: int, tmp: str):
    """Train one run; returns ``(trainer, seconds)``."""
    from a2cm_phys.config import load_scenario, load_train
    from a2cm_phys.trainer import Trainer

    cfg = load_train({"seed": seed, "updates": updates})
    trainer = Trainer(load_scenario(scenario), cfg, tmp, record=False)
    start = time.perf_counter()
    assert trainer.run() == "done"
    return trainer, time.perf_counter() - start


def measure(seed: int, updates: int) -> dict:
    """Train both kinds of pursuers for ``seed`` and fill the exact cross-play table."""
    import torch

    from a2cm_phys.config import load_scenario
    from a2cm_phys.oracle import load_or_solve
    from a2cm_phys.solve.best_response import evader_best_response, evaluate_tables
    from a2cm_phys.solve.tables import joint_policy_table, model_table, scripted_evader_table

    torch.set_num_threads(1)
    game = load_scenario("grid")  # the rules every table is evaluated under
    with tempfile.TemporaryDirectory() as a, tempfile.TemporaryDirectory() as b:
        single, single_s = train("grid", seed, updates, a)
        selfplay, selfplay_s = train("grid_vs", seed, updates, b)
    oracle = joint_policy_table(game, load_or_solve(game).policy)
    pursuers = {
        "random-trained": model_table(game, single.model, game.pursuers),
        "self-play": model_table(game, selfplay.model, game.pursuers),
        "oracle": oracle,
    }
    assert selfplay.evader is not None
    evaders = {
        "random": scripted_evader_table(game, "random"),
        "flee": scripted_evader_table(game, "flee"),
        "learned": model_table(game, selfplay.evader.model, 1),
    }
    table = {}
    for p, ptable in pursuers.items():
        for e, etable in evaders.items():
            out = evaluate_tables(game, ptable, etable)
            table[p, e] = float(out.values[start_index(game)])
        table[p, "best-response"] = evader_best_response(game, ptable).value_from_start
    return {
        "seed": seed,
        "table": table,
        "single_steps_s": single.summary()["steps_per_s"],
        "selfplay_steps_s": selfplay.summary()["steps_per_s"],
        "single_s": single_s,
        "selfplay_s": selfplay_s,
    }


def start_index(scenario) -> int:
    """The joint state of the default start."""
    from a2cm_phys.solve.tables import start_state

    return start_state(scenario)


def throughput(updates: int, repeats: int) -> list[tuple[float, float]]:
    """Steps/s of ``grid_vs`` with its evader scripted (random) and learned, interleaved."""
    from a2cm_phys.config import load_scenario, load_train
    from a2cm_phys.trainer import Trainer

    out = []
    for _ in range(repeats):
        pair = []
        for evader in ("random", "learned"):
            sc = load_scenario("grid_vs", {"evader": evader})
            with tempfile.TemporaryDirectory() as tmp:
                t = Trainer(sc, load_train({"updates": updates}), tmp, record=False)
                t.run()
                pair.append(t.summary()["steps_per_s"])
        out.append((pair[0], pair[1]))
    return out


def main() -> int:
    """Run the seeds and print the cross-play table (medians over seeds) and throughput."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seeds", default="0-4")
    p.add_argument("--updates", type=int, default=5000)
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--throughput-updates", type=int, default=1000)
    p.add_argument("--throughput-repeats", type=int, default=3)
    args = p.parse_args()
    lo, _, hi = args.seeds.partition("-")
    seeds = list(range(int(lo), int(hi or lo) + 1))
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = list(pool.map(measure, seeds, [args.updates] * len(seeds)))
    print("command: python benchmarks/bench_selfplay.py " + " ".join(sys.argv[1:]))
    print("\nExact expected capture time E[min(T, 1000)] from the default start, median over")
    print(f"seeds {args.seeds} (each seed's value in brackets):\n")
    print("| pursuers | " + " | ".join(f"{e} evader" for e in EVADERS) + " |")
    print("|---|" + "---|" * len(EVADERS))
    for pursuer in PURSUERS:
        cells = []
        for e in EVADERS:
            values = [r["table"][pursuer, e] for r in rows]
            each = ", ".join(f"{v:.3f}" for v in values)
            cells.append(f"{statistics.median(values):.3f} ({each})")
        print(f"| {pursuer} | " + " | ".join(cells) + " |")
    for key in ("single_s", "selfplay_s"):
        print(f"{key}: median {statistics.median(r[key] for r in rows):.1f} s")
    pairs = throughput(args.throughput_updates, args.throughput_repeats)
    ratios = [b / a for a, b in pairs]
    print("\nthroughput, grid_vs, scripted (random) vs learned evader, interleaved pairs:")
    for (a, b), r in zip(pairs, ratios, strict=True):
        print(f"  scripted {a:,.0f} steps/s, self-play {b:,.0f} steps/s: {r:.2f}")
    print(f"  median ratio {statistics.median(ratios):.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
