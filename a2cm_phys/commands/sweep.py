"""``python -m a2cm_phys.sweep``: scenarios × algorithms × seeds, each run a Ray task (or
one after another without Ray).

    python -m a2cm_phys.sweep --scenarios grid,grid_collision --algos a2c,a2cm --seeds 0-4

Parses the options into run specs and prints each run's fate and the summary table; the
sweep itself (reuse of finished runs, found by their configuration, the runs' locks,
retries, stopping on a signal) is :mod:`a2cm_phys.study.launch`. A run's directory is
``<logdir>/<scenario>-<algo>[-<preset>]-s<seed>/``.
"""

from __future__ import annotations

import argparse
import signal
import sys
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from ..config import ConfigError, load_scenario
from .options import (
    Parser,
    UsageError,
    add_logdir,
    add_scenario_options,
    check_device,
    int_range,
    positive_float,
    run_cli,
    split_assignments,
    train_values,
    writable_dir,
)

if TYPE_CHECKING:  # the study's modules (torch, ray) are imported once the options are parsed
    from ..study.runspec import RunSpec

_MAX_SEEDS = 10_000


def parse_seeds(text: str) -> list[int]:
    """``0-4`` → 0..4; ``1,3,7`` → those; both may mix (``0-2,9``); a seed given twice, a
    negative one or one beyond 64 bits is a :class:`ConfigError`."""
    from .options import MAX_SEED

    seeds: list[int] = []
    for part in text.split(","):
        lo, _, hi = part.strip().partition("-")
        try:
            first, last = int(lo), int(hi or lo)
        except ValueError:
            raise ConfigError(f"--seeds: '{text}' is not like 0-4 or 1,3,7") from None
        if last - first >= _MAX_SEEDS or len(seeds) >= _MAX_SEEDS:
            raise ConfigError(f"--seeds: '{text}': too many seeds (at most {_MAX_SEEDS:,})")
        seeds += range(first, last + 1)
    if not seeds:
        raise ConfigError(f"--seeds: '{text}' gives no seed")
    repeated = sorted(s for s, n in Counter(seeds).items() if n > 1)
    if repeated:
        raise ConfigError(f"--seeds: seed {repeated[0]} is given twice in '{text}'")
    if max(seeds) > MAX_SEED:
        raise ConfigError(f"--seeds: {max(seeds)} is beyond 64 bits")
    return seeds


def _names(text: str, option: str) -> list[str]:
    names = [x.strip() for x in text.split(",") if x.strip()]
    if not names:
        raise ConfigError(f"{option}: '{text}' names nothing")
    repeated = sorted({x for x in names if names.count(x) > 1})
    if repeated:
        raise ConfigError(f"{option}: '{repeated[0]}' is given twice")
    return names


def build_parser() -> argparse.ArgumentParser:
    """The ``python -m a2cm_phys.sweep`` argument parser."""
    p = Parser(
        prog="python -m a2cm_phys.sweep",
        description="Scenarios × algorithms × seeds, each run a Ray task (or one after another"
        " without Ray);\nfinished runs are found by their configuration and skipped.",
    )
    p.add_argument(
        "--scenarios", required=True, help="comma-separated scenario names or TOML paths"
    )
    p.add_argument("--algos", default="a2c,a2cm", help="comma-separated: a2c, a2cm")
    p.add_argument(
        "--live",
        nargs="?",
        const="",
        metavar="[HOST:]PORT",
        help="refused: a sweep's runs are many; watch one with train --live (default: off)",
    )
    p.add_argument("--seeds", default="0-4", help="e.g. 0-4 or 1,3,7")
    p.add_argument(
        "--updates",
        type=int_range(1),
        help="gradient updates of each run (default: 5000; continuous control: 2,000,000"
        " steps' worth, 4,000,000 against the fleeing evader)",
    )
    add_logdir(p, "logs/sweep", "where the run directories go (--sweep-dir: the old spelling)")
    p.add_argument(
        "--address",
        help="Ray cluster address: auto, ray://host:10001 (default: start Ray on this machine)",
    )
    p.add_argument(
        "--cpus-per-run", type=positive_float, default=1.0, help="CPUs Ray gives each run"
    )
    p.add_argument("--sequential", action="store_true", help="no Ray, even if installed")
    add_scenario_options(p, scenario=False)
    p.add_argument("--no-record", action="store_true", help="no MCAP episode logs")
    p.add_argument(
        "--log-every",
        type=int_range(0),
        default=1,
        help="log every K-th episode's trajectory; 0: none",
    )
    return p


def plan(args: argparse.Namespace) -> list[RunSpec]:
    """The runs of a sweep, validated (also against the run directories already in
    ``--logdir``, found by their configuration) before anything starts."""
    from ..study.rundirs import check_reusable, existing_runs, find_run
    from ..study.runspec import RunSpec

    overrides, _ = split_assignments(args.set)
    train = train_values(args, {"updates": args.updates})
    scenarios = _names(args.scenarios, "--scenarios")
    algos = _names(args.algos, "--algos")
    seeds = parse_seeds(args.seeds)
    specs, names = [], {}
    for scenario in scenarios:
        load_scenario(scenario, overrides)
        for algo in algos:
            for seed in seeds:
                spec = RunSpec(
                    scenario,
                    algo,
                    seed,
                    train,
                    overrides,
                    not args.no_record,
                    args.log_every,
                    args.preset,
                )
                _, cfg = spec.resolve()
                if spec.name in names:
                    raise ConfigError(
                        f"--scenarios: '{names[spec.name]}' and '{scenario}' would share the run"
                        f" directory {spec.name}"
                    )
                names[spec.name] = scenario
                specs.append(spec)
    check_device(cfg.device)
    sweep_dir = writable_dir(args.logdir, "--logdir")  # refuses '' and links to nothing
    existing = existing_runs(sweep_dir)
    for spec in specs:
        check_reusable(spec, find_run(spec, sweep_dir, existing))
    return specs


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m a2cm_phys.sweep``; returns the exit status."""
    return run_cli(_main, argv)


def _main(argv: Sequence[str]) -> int:
    args = build_parser().parse_args(argv)
    if args.live is not None:
        raise UsageError(
            "--live: a sweep trains many runs, and a live view shows one; train one run"
            " with python -m a2cm_phys.train --scenario NAME --live, or open a finished"
            " run's log in Foxglove (replay RUN --serve)"
        )
    from ..study.stopping import stop_signals

    with stop_signals() as received:
        try:
            return _sweep(args)
        except KeyboardInterrupt as stop:
            signum = received.behind(stop)
            print(
                f"interrupted ({signal.Signals(signum).name}): finished runs are intact, stopped"
                " ones resume from their checkpoints; run the same command to resume",
                file=sys.stderr,
            )
            return 128 + signum


def _sweep(args: argparse.Namespace) -> int:
    from ..study.launch import run_all
    from ..study.results import Outcome, format_table, summarise, write_summary
    from ..study.watch import RunsProgress

    specs = plan(args)
    sweep_dir = Path(args.logdir)
    sweep_dir.mkdir(parents=True, exist_ok=True)
    with RunsProgress("sweep", len(specs)) as progress:

        def on_done(o: Outcome) -> None:
            progress.finished(o.spec.name, f"{o.name}: {o.describe()}")

        outcomes, _ = run_all(
            specs,
            sweep_dir,
            on_done,
            args.address,
            args.cpus_per_run,
            args.sequential,
            on_start=lambda spec: progress.started(spec.name),
        )
    rows = summarise(outcomes)
    written = write_summary(rows, outcomes, sweep_dir)
    if rows:
        print(format_table(rows))
    failed = [o for o in outcomes if o.error]
    for o in failed:
        print(f"FAILED {o.name} after {o.attempts} attempts: {o.error}", file=sys.stderr)
    for o in outcomes:
        if o.busy is not None:
            print(f"BUSY {o.name}: {o.busy}; not run", file=sys.stderr)
    print(f"summary: {', '.join(str(p) for p in written)}")
    if failed and len(failed) == len(outcomes):
        print(f"error: every run failed ({len(failed)} of {len(outcomes)})", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
