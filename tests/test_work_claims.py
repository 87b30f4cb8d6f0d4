"""The report's claims on the later issues' work: each target tested on the benchmarks'
records (or the report's own export checks), a missed target given its row and verdict."""

from __future__ import annotations

import json
from pathlib import Path

from a2cm_phys.study.report.work_claims import (
    oracle_claims,
    parity_claims,
    peer_claims,
    random_start_claims,
    recurrent_claims,
    scale_claims,
    speed_claims,
    within_claims,
    work_claims,
)


def pomdp_rows(memoryless: list[float], recurrent: list[float], steps: int = 640_000) -> list:
    row = {"scenario": "grid_pomdp", "algo": "a2cm", "train_steps": steps}
    rows = [{**row, "recurrent": "none", "mean_steps": x} for x in memoryless]
    rows += [{**row, "recurrent": "gru", "mean_steps": x} for x in recurrent]
    return rows


def test_recurrent_target_verdicts() -> None:
    (missed,) = recurrent_claims(pomdp_rows([3.0, 3.1, 3.05], [3.02, 3.08, 3.1]))
    assert missed.verdict == "does not hold" and missed.sizes == (3, 3)
    assert "(1.00" in missed.measured and missed.scope == "grid_pomdp, A2CM"
    (met,) = recurrent_claims(pomdp_rows([4.0, 4.1, 4.05], [3.0, 3.05, 3.1]))
    assert met.verdict == "holds"
    (one,) = recurrent_claims(pomdp_rows([4.0], [3.0]))
    assert one.verdict == "inconclusive" and one.evidence == "n = 1"
    assert recurrent_claims(pomdp_rows([], [3.0])) == []  # nothing to compare with


def test_recurrent_claims_compare_runs_of_equal_steps() -> None:
    """A scenario trained for two budgets (the 9×9 runs, then longer) gets a claim per
    budget, each recurrent team against the memoryless one of its own budget."""
    rows = pomdp_rows([4.0, 4.1, 4.05], [3.9, 4.0, 4.0])
    rows += pomdp_rows([3.6, 3.7, 3.65], [2.5, 2.55, 2.6], steps=2_560_000)
    short, long = recurrent_claims(rows)
    assert short.scope == "grid_pomdp, A2CM, 640,000 steps" and short.verdict == "does not hold"
    assert long.scope == "grid_pomdp, A2CM, 2,560,000 steps" and long.verdict == "holds"


def test_random_start_targets_against_the_optimum_over_starts() -> None:
    def row(scenario: str, steps: float, optimum: float) -> dict:
        own = {"steps": steps, "optimum": optimum, "collisions": 0.1, "capture_rate": 1.0}
        return {"scenario": scenario, "algo": "a2cm", "own": own}

    rows = [row("grid_random", x, 2.575) for x in (2.66, 2.67, 2.665)]
    rows += [row("grid_collision_random", x, 2.579) for x in (2.9, 2.92, 2.89)]
    rows += [row("grid_collision", 2.94, 2.939)]  # the fixed start: no such target here
    collision, plain = random_start_claims(rows)
    assert plain.verdict == "holds" and plain.sizes == (3,) and "issue 45" in plain.claim
    assert collision.verdict == "does not hold" and "optimum 2.5790" in collision.scope


def test_peer_claims_pair_seeds_at_equal_steps() -> None:
    def row(algo: str, seed: int, steps: float, variant: str = "tuned") -> dict:
        return {"scenario": "grid_collision", "steps": 640_000, "algo": algo, "seed": seed,
                "variant": "ours" if algo.startswith("a2c") else variant,
                "mean_steps": steps}  # fmt: skip

    rows = [row("a2cm", k, 2.95) for k in range(3)]
    rows += [row("mappo", k, x) for k, x in enumerate((9.0, 5.0, 9.5))]
    rows += [row("ippo", 0, 2.9), row("ippo", 7, 1.0)]  # seed 7 has no A2CM run to pair with
    rows += [row("mappo", 0, 1.0, "defaults"), row("a2c", 0, 1.0)]  # neither is compared
    ippo, mappo = peer_claims(rows)
    assert mappo.verdict == "holds" and mappo.sizes == (3,) and "MAPPO" in mappo.claim
    assert ippo.sizes == (1,) and ippo.verdict == "inconclusive"


def scale_row(config: str, seed: int, steps: float, reference: float, policy: str) -> dict:
    return {"config": config, "seed": seed, "cap": 5_000_000, "scenario": config[:-3],
            "size": 10, "pursuers": 3, "reference": reference, "reference_policy": policy,
            "last_mean_steps": steps}  # fmt: skip


def test_scale_targets_against_their_reference() -> None:
    rows = [scale_row("grid10x3", s, x, 8.0, "optimum") for s, x in enumerate((8.3, 8.4, 8.2))]
    rows += [scale_row("phys_cont10x3", s, x, 50.0, "pursuit") for s, x in
             enumerate((118.0, 140.0, 190.0))]  # fmt: skip
    grid, phys = scale_claims(rows)
    assert grid.verdict == "holds" and "the exact optimum" in grid.claim
    assert phys.verdict == "does not hold" and "`pursuit`" in phys.claim
    assert phys.sizes == (3,)


def test_oracle_scale_is_exact() -> None:
    row = {"scenario": "grid", "size": 10, "pursuers": 3, "capture_steps": 8.0371,
           "peak_gib": 0.7, "seconds": 197.0}  # fmt: skip
    (claim,) = oracle_claims([{**row, "size": 9}, row])
    assert claim.verdict == "holds" and "10×10: 8.0371" in claim.measured
    (claim,) = oracle_claims([{**row, "size": 9}])
    assert claim.verdict == "does not hold"  # the largest arena asked was never solved
    (claim,) = oracle_claims([{**row, "peak_gib": 9.5}])
    assert claim.verdict == "does not hold"
    assert oracle_claims([]) == []


def test_speed_target_from_recorded_pairs() -> None:
    rows = [{"scenario": "grid_collision", "peer": "61cf8cf",
             "pairs": [[10.0, 18.0], [10.5, 18.4], [12.0, 21.2], [10.6, 18.1]]}]  # fmt: skip
    (claim,) = speed_claims(rows)
    assert claim.verdict == "does not hold" and claim.sizes == (4,)  # every pair above 0.5
    rows[0]["pairs"] = [[8.0, 18.0], [8.2, 18.4], [9.0, 21.2]]
    assert speed_claims(rows)[0].verdict == "holds"


def test_parity_rows() -> None:
    good = {"observations": 10_000, "max_abs_diff": 1e-6, "max_scaled_diff": 1e-6,
            "agreement": 1.0}  # fmt: skip
    cells = {"ours/grid/a2cm": [good, good], "descent/grid_vs/a2c": [good],
             "continuous/phys_cont/a2cm": [good]}  # fmt: skip
    discrete, continuous = parity_claims(cells)
    assert discrete.verdict == "holds" and discrete.scope.startswith("discrete control: 2 cells")
    assert "3 runs: greedy actions agree 100.00% of 30,000" in discrete.measured
    assert continuous.scope == "continuous control: 1 cell of continuous"
    refused = {"observations": 10_000, "error": "the exported actors differ"}
    (claim,) = parity_claims({"ours/grid/a2cm": [good, refused]})
    assert claim.verdict == "does not hold" and "1 of 2 exports refused" in claim.measured
    off = {**good, "agreement": 0.9999}
    assert parity_claims({"ours/grid/a2cm": [good, off]})[0].verdict == "does not hold"


def test_records_folder(tmp_path: Path) -> None:
    assert work_claims(None, {}) == [] and work_claims(tmp_path, {}) == []
    lines = [json.dumps(r) for r in pomdp_rows([3.0, 3.1], [3.0, 3.1])]
    (tmp_path / "pomdp.jsonl").write_text("\n".join(lines) + "\n\n")
    (claim,) = work_claims(tmp_path, {})
    assert "issue 33" in claim.claim


def test_within_target_reads_the_shipped_defaults_only() -> None:
    def row(variant: str, algo: str, greedy: float) -> dict:
        return {"scenario": "grid_flee", "variant": variant, "algo": algo, "greedy": greedy,
                "reference": 3.948}  # fmt: skip

    rows = [row("ours", "a2cm", x) for x in (6.1, 5.9, 6.3)]
    rows += [row("ours+onehot", "a2cm", 3.95), row("ours", "a2c", 4.0), row("ours", "a2c", 4.1)]
    rows += [{**row("ours", "a2cm", 3.0), "scenario": "grid"}]  # no target there
    a2c, a2cm = within_claims(rows)
    assert a2cm.verdict == "does not hold" and a2cm.sizes == (3,)  # ablations not counted
    assert "within 5% of the exact optimum (grid_flee)" in a2cm.claim
    assert a2c.sizes == (2,) and a2c.verdict == "inconclusive"  # 1.026×, a wide interval
