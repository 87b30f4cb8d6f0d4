"""Where a trained greedy team loses time against the optimum, exactly (grid scenarios).

    python benchmarks/greedy_loss.py RUN_DIR [--top 12]

The greedy joint policy of the run's actors is replayed through the exact grid rule
(:func:`~a2cm_phys.solve.policy_chain.policy_chain`) against the scenario's scripted evader.
From the default start, its expected capture time exceeds the optimum's by exactly
``Σ_s visits(s) · (Q*(s, π(s)) − V*(s))``: each state's expected visits under the policy
times the steps its chosen joint action loses by the oracle's values. The script prints
that sum, and the states that contribute most, with the team's actions, the oracle's, and
each actor's largest probability. A probability of 1.00 on a losing action is an actor
that stopped exploring there (``BENCHMARKS.md``, "The entropy coefficient and its
schedule").
"""

from __future__ import annotations

import argparse

import numpy as np

from a2cm_phys.analysis.sources import load_pursuer_run
from a2cm_phys.solve.cache import load_or_solve
from a2cm_phys.solve.policy_chain import evaluate_policy, policy_chain, state_visits
from a2cm_phys.solve.tables import model_table, start_state


def main() -> None:
    """Print the greedy team's loss against the optimum and the states it comes from."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("run", help="a run directory of a grid scenario with a scripted evader")
    p.add_argument("--top", type=int, default=12, help="states to list")
    args = p.parse_args()
    scenario, model = load_pursuer_run(args.run)
    solution = load_or_solve(scenario)
    grid = solution.model
    table = model_table(scenario, model, scenario.pursuers)  # (S, N, A)
    greedy = table.argmax(-1)
    joint = np.ravel_multi_index(tuple(greedy.T), (scenario.actions,) * scenario.pursuers)
    chain = policy_chain(grid, joint)
    steps = evaluate_policy(chain, np.ones(grid.n_states), skip=~grid.valid())
    start = start_state(scenario)
    optimum = solution.steps
    visits = state_visits(chain, start, scenario.max_steps)
    q = 1.0 + np.einsum("sb,sb->s", chain.cont, np.nan_to_num(optimum)[chain.next])
    loss = visits * (q - optimum)
    print(
        f"greedy {steps[start]:.4f} steps, optimum {optimum[start]:.4f}: "
        f"{steps[start] - optimum[start]:.4f} lost; Σ visits·loss = {np.nansum(loss):.4f}"
    )
    oracle = grid.joint_to_actions(solution.policy)
    for s in np.argsort(-np.nan_to_num(loss))[: args.top]:
        cells = grid.decode(np.array([s]))[:, 0]
        where = " ".join(f"({c // scenario.size},{c % scenario.size})" for c in cells)
        print(
            f"state {s}: pursuers, evader {where}  visits {visits[s]:.3f}  "
            f"loses {q[s] - optimum[s]:.3f} steps  team {greedy[s].tolist()}  "
            f"oracle {oracle[s].tolist()}  largest probabilities {table[s].max(-1).round(2)}"
        )


if __name__ == "__main__":
    main()
