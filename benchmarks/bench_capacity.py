"""Can an actor network represent an unexploitable pursuer team? (issue 14's worst case)

    python benchmarks/bench_capacity.py --hidden 128 --layers 1 --encoding xy --epochs 8

The minimax team (``a2cm_phys/solve/minimax.py``) escapes no evader for more than 6 steps
from the start, and so does *every* team that, in every joint state, picks a joint action
whose pursuers-first value is optimal (each step then lowers that value by one). This
script fits decentralised actors (one softmax per pursuer over the global observation, as
our A2CM actors) to put their joint probability on that optimal set, by supervised learning
on all 390,625 joint states of ``grid_vs`` (loss ``-log Σ_{a optimal} Π_i π_i(a_i|s)``, Adam
1e-3, batches of 512), and after each epoch measures the exact worst case (the evader's
best response, horizon ``--horizon``) of the sampled actors and of their greedy actions.

This is the easiest setting a learner could have: every state labelled, every optimal
action accepted. A network that cannot get below the oracle's 10 steps here cannot get
there by self-play either. ``--encoding xy`` is the observation of SPEC §5 (coordinates
divided by ``size - 1``); ``onehot`` feeds each coordinate as a one-hot of its cell.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time

import numpy as np
import torch

from a2cm_phys.config import load_scenario
from a2cm_phys.solve.best_response import evader_best_response
from a2cm_phys.solve.minimax import CHUNK, minimax_bounds, transitions
from a2cm_phys.solve.tables import joint_observations, n_states, valid_states


def optimal_joint_actions(scenario) -> np.ndarray:
    """``(S, A^N)`` bool: the joint actions whose pursuers-first value is optimal."""
    bounds = minimax_bounds(scenario)
    nxt = transitions(scenario)
    value = np.append(bounds.upper, 0.0)  # the capture sentinel is worth 0 steps
    mask = np.zeros(nxt.shape[:2], dtype=bool)
    for lo in range(0, len(mask), CHUNK):
        part = slice(lo, min(len(mask), lo + CHUNK))
        mask[part] = value[nxt[part]].max(axis=2) + 1 == bounds.upper[part, None]
    return mask


def encode(obs: torch.Tensor, encoding: str, size: int) -> torch.Tensor:
    """The network's input: the observation, or one one-hot of each coordinate's cell."""
    if encoding == "xy":
        return obs
    cells = torch.round(obs * (size - 1)).long()
    return torch.nn.functional.one_hot(cells, size).float().flatten(1)


def joint_probs(logits: torch.Tensor, n: int, a: int) -> torch.Tensor:
    """``(B, A^N)`` joint action probabilities of ``n`` independent softmax actors, in the
    oracle's joint index order ``(a_0 · A + a_1) · A + …``."""
    p = torch.softmax(logits.view(-1, n, a), -1)
    out = p[:, 0]
    for i in range(1, n):
        out = (out[:, :, None] * p[:, i, None, :]).flatten(1)
    return out


def main() -> None:
    """Fit, then print one JSON line per epoch with the exact worst cases."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--hidden", type=int, default=128)
    p.add_argument("--layers", type=int, default=1)
    p.add_argument("--encoding", choices=("xy", "onehot"), default="xy")
    p.add_argument("--epochs", type=int, default=8)
    p.add_argument("--horizon", type=int, default=200)
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args()
    torch.manual_seed(args.seed)
    torch.set_num_threads(1)
    scenario = dataclasses.replace(
        load_scenario("grid_vs"), evader="random", max_steps=args.horizon
    )
    n, a = scenario.pursuers, scenario.actions
    mask = torch.as_tensor(optimal_joint_actions(scenario))
    states = torch.as_tensor(np.flatnonzero(valid_states(scenario)))
    x = encode(torch.as_tensor(joint_observations(scenario)), args.encoding, scenario.size)
    layers: list[torch.nn.Module] = []
    width = x.shape[1]
    for _ in range(args.layers):
        layers += [torch.nn.Linear(width, args.hidden), torch.nn.ReLU()]
        width = args.hidden
    net = torch.nn.Sequential(*layers, torch.nn.Linear(width, n * a))
    optimizer = torch.optim.Adam(net.parameters(), lr=1e-3)
    t0 = time.perf_counter()
    for epoch in range(1, args.epochs + 1):
        for batch in states[torch.randperm(len(states))].split(512):
            mass = (joint_probs(net(x[batch]), n, a) * mask[batch]).sum(1)
            loss = -torch.log(mass + 1e-12).mean()
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
        with torch.no_grad():
            logits = torch.cat([net(x[c]) for c in torch.arange(n_states(scenario)).split(1 << 16)])
            mass = (joint_probs(logits, n, a) * mask).sum(1)[states]
        table = torch.softmax(logits.view(-1, n, a), -1).double().numpy()
        greedy = np.zeros_like(table)
        np.put_along_axis(greedy, table.argmax(-1)[..., None], 1.0, -1)
        print(
            json.dumps(
                {
                    **vars(args),
                    "epoch": epoch,
                    "mean_optimal_mass": round(float(mass.mean()), 4),
                    "worst_case_sampled": evader_best_response(scenario, table).value_from_start,
                    "worst_case_greedy": evader_best_response(scenario, greedy).value_from_start,
                    "seconds": round(time.perf_counter() - t0, 1),
                }
            ),
            flush=True,
        )


if __name__ == "__main__":
    main()
