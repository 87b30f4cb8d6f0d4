"""What ``python -m a2cm_phys.oracle`` prints for a solved optimum: the solve, the start,
the optimal return and the law of the capture time, from the dense solver or the symmetric
one (arenas the dense one cannot hold)."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the solvers (numpy arrays, torch) are imported after parsing
    from ..solve.cache import OracleSolution
    from ..solve.symmetric import SymmetricResult


def optimum_report(sol: OracleSolution | SymmetricResult) -> str:
    """The oracle command's report of ``sol`` (see the module)."""
    import numpy as np

    from ..solve.symmetric import SymmetricResult

    sc = sol.scenario
    start = sol.start_positions()
    dist = sol.distribution()
    cells = " ".join(f"({x},{y})" for x, y in start[:-1])
    lines = [
        f"oracle: {sc.name}: {sc.size}x{sc.size} grid, {sc.pursuers} pursuer(s), "
        f"{sc.actions} actions, {sc.evader} evader, collisions {sc.collisions.mode}",
        *(_symmetric_lines(sol) if isinstance(sol, SymmetricResult) else _dense_lines(sol)),
        f"  start: pursuers {cells}, evader ({start[-1][0]},{start[-1][1]})",
        f"  optimal expected return: {sol.optimal_return(start):.6f}",
        f"  expected steps to capture: {sol.expected_capture_steps(start):.6f}",
    ]
    if sc.obstacles:
        blocked = np.flatnonzero(sc.blocked_cells())
        where = " ".join(f"({c % sc.size},{c // sc.size})" for c in blocked)
        lines.insert(1, f"  obstacles: {len(blocked)} blocked cell(s) {where}")
    if sc.start.random:
        from ..envs.starts import count_grid_starts

        free = ", none on a blocked cell" if sc.obstacles else ""
        lines[-3] = (
            f"  start: random, uniform over {count_grid_starts(sc):,} starts (every pursuer "
            f"at Manhattan distance >= {sc.start.min_evader_distance:g} from the evader{free})"
        )
        lines[-2] = f"  optimal expected return over the starts: {sol.start_value:.6f}"
        lines[-1] = f"  expected steps to capture over the starts: {sol.start_steps:.6f}"
    if not np.isfinite(sol.start_value):
        lines.append("  capture cannot be forced from the start: no finite optimum")
        return "\n".join(lines)
    if sc.collisions.mode != "off" and not isinstance(sol, SymmetricResult):
        lines.append(
            f"  P(capture) {dist.p_capture:.6f}, P(ended by collision) "
            f"{dist.collision.sum():.2e}, expected collisions "
            f"{float(sol.start_law[1] @ sol.collisions[sol.start_law[0]]):.2e}"
        )
    median, p95 = dist.quantile(0.5), dist.quantile(0.95)
    lines.append(
        f"  capture steps: mean {dist.mean_length():.6f}, median {median:g}, p95 {p95:g}, "
        f"p99 {dist.quantile(0.99):g}, P(truncated at {sc.max_steps}) {dist.truncated:.1e}"
    )
    top = int(min(dist.quantile(0.999), 20)) if np.isfinite(dist.quantile(0.999)) else 20
    cdf = ", ".join(f"{k}: {dist.cdf(k):.4f}" for k in range(1, top + 1))
    lines.append(f"  P(capture <= k): {cdf}")
    return "\n".join(lines)


def _dense_lines(sol: OracleSolution) -> list[str]:
    meta = sol.meta
    state = "loaded from" if sol.cached else ("saved to" if sol.path else "not cached")
    peak = meta.get("peak_bytes")
    lines = [
        f"  solve: {meta['states']:,} joint states x {meta['joint_actions']} joint actions, "
        f"{meta['sweeps']} sweeps (+{meta['qualitative_sweeps']} reachability), residual "
        f"{meta['residual']:.1e}, {meta['seconds']:.1f} s"
        + (f", peak {peak / 2**20:.0f} MiB" if peak else ""),
        f"  check: greedy policy replayed through GridRules.apply matches the optimum to "
        f"{meta['policy_check']:.1e}",
        f"  cache: {state} {sol.path}" if sol.path else f"  cache: {state}",
    ]
    if meta["losing_states"]:
        lines.append(f"  {meta['losing_states']:,} states from which capture cannot be forced")
    return lines


def _symmetric_lines(sol: SymmetricResult) -> list[str]:
    sc = sol.scenario
    n = sc.pursuers
    joint = sc.size ** (2 * (n + 1))
    lines = [
        f"  solve (symmetric): {joint:,} joint states, {sol.index.n:,} up to symmetry (the"
        f" square's 8 rotations and reflections x the pursuers' {n}! orders),"
        f" {sol.greedy_sweeps} greedy + {sol.evaluation_sweeps} evaluation sweeps, residual"
        f" {sol.residual:.1e}, {sol.seconds:.1f} s, memory estimate"
        f" {sol.memory_estimate / 2**30:.2f} GiB",
    ]
    if sc.collisions.mode == "terminate":
        lines.append("  (capture steps below count every end: captures and collisions)")
    return lines
