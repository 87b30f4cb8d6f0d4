"""Sweeps of scenarios × algorithms × seeds, each run a Ray task (or sequential without Ray).

    python -m a2cm_phys.sweep --scenarios grid,grid_collision --algos a2c,a2cm --seeds 0-4

Each run is exactly ``python -m a2cm_phys.train`` with that scenario, algorithm and seed,
written to its own run directory ``<logdir>/<scenario>-<algo>[-<preset>]-s<seed>/``
(config, checkpoint, MCAP log, summary), so a sweep's numbers equal those of the runs done
one by one. Re-running a sweep skips finished runs and resumes unfinished ones from their
checkpoints; an existing run is found by its resolved scenario and training config, not its
name (runs named before the preset was part of the name are found too), and a run
directory of the new run's name holding another configuration is an error naming the
difference, found before anything runs. A failing run is retried once and reported while the
others go on. Each run holds its run directory's lock
(:func:`a2cm_phys.training.rundir.run_lock`) while it runs: a run that another process
writes (a ``train``, or a second sweep on the same ``--logdir``) is reported busy and left
alone, so no run is ever written twice at once. Ctrl-C or SIGTERM stop the sweep cleanly:
running runs save their checkpoints, the exit status is 130 or 143, and the same command
resumes. Without ``--address`` Ray starts locally on this machine's cores; ``--address
auto`` or ``ray://host:10001`` uses an existing cluster. Without Ray installed (``pip
install -e ".[cluster]"``) the runs go one after another in this process.

This module launches the runs (:func:`run_all`: on Ray or one by one); a run's spec is
:mod:`.runspec`, its run directory's bookkeeping and its execution :mod:`.rundirs`, the
outcomes and the sweep's table :mod:`.results`, stopping on a signal :mod:`.stopping`."""

from __future__ import annotations

import contextlib
import signal
import sys
import traceback
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from ..training.rundir import write_atomic
from .results import Outcome
from .rundirs import execute
from .runspec import RunSpec
from .stopping import Interrupted, Received, handlers_kept, stop_signals


def run_sequential(
    specs: Sequence[RunSpec],
    sweep_dir: Path,
    on_done: Callable[[Outcome], None],
    on_start: Callable[[RunSpec], None] | None = None,
) -> list[Outcome]:
    """Run the specs one by one in this process, retrying each failure once (a busy run is
    not retried), calling ``on_start`` before each; Ctrl-C or SIGTERM raise
    :class:`Interrupted` once the running run has saved its checkpoint."""
    outcomes = []
    with stop_signals():
        for spec in specs:
            if on_start is not None:
                on_start(spec)
            outcome = Outcome(spec)
            for attempt in (1, 2):
                outcome.attempts = attempt
                try:
                    outcome.take(execute(spec, str(sweep_dir)))
                    break
                except KeyboardInterrupt:
                    raise
                except Exception as err:  # a run's failure must not stop the sweep
                    outcome.error = f"{type(err).__name__}: {err}"
                    tb = traceback.format_exc(limit=3)
                    write_atomic(sweep_dir / f"{spec.name}.error.txt", tb)
            outcomes.append(outcome)
            on_done(outcome)
    return outcomes


_STOP_WAIT_S = 300.0
"""How long a stopped sweep waits for its running runs to save their checkpoints."""


def run_on_ray(
    specs: Sequence[RunSpec],
    sweep_dir: Path,
    on_done: Callable[[Outcome], None],
    address: str | None,
    cpus_per_run: float,
) -> list[Outcome]:
    """Run each spec as a Ray task (retried once on error or worker death; a busy run is
    not retried). Starts or joins Ray unless it is initialised already (then it is left as
    it is); Ctrl-C or SIGTERM cancel the tasks, wait for the running ones to save their
    checkpoints, shut Ray down and raise :class:`Interrupted`."""
    import ray

    owned = not ray.is_initialized()
    # ray.init installs its own SIGTERM handler (sys.exit, and a stack dump): the sweep's
    # are installed over it, and this process's are back once Ray is shut down
    with handlers_kept():
        try:
            if owned:
                _init_ray(ray, address)
            with stop_signals() as received:
                return _wait_on_ray(ray, specs, sweep_dir, on_done, cpus_per_run, received)
        finally:
            if owned:
                with stop_signals("shutting Ray down"):
                    ray.shutdown()


def _init_ray(ray: Any, address: str | None) -> None:
    """Start (or join) Ray with the smallest footprint this Ray allows: no dashboard, no
    worker output in the driver (its raylet still starts a dashboard agent and a runtime-env
    agent; after a SIGKILL of the driver they outlive it by about a minute)."""
    try:
        ray.init(address=address, include_dashboard=False, log_to_driver=False)
    except SystemExit as stop:  # ray.init's own SIGTERM handler: sys.exit(signum)
        if stop.code == signal.SIGTERM:
            raise Interrupted(signal.SIGTERM) from None
        raise


def _wait_on_ray(
    ray: Any,
    specs: Sequence[RunSpec],
    sweep_dir: Path,
    on_done: Callable[[Outcome], None],
    cpus_per_run: float,
    received: Received,
) -> list[Outcome]:
    task = ray.remote(num_cpus=cpus_per_run, max_retries=1, retry_exceptions=True)(execute)
    pending = {task.remote(spec, str(sweep_dir.resolve())): spec for spec in specs}
    outcomes = []
    try:
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1)
            spec = pending.pop(ready[0])
            outcome = Outcome(spec, attempts=0)
            try:
                outcome.take(ray.get(ready[0]))
            except Exception as err:  # RayTaskError wraps the run's exception
                cause = getattr(err, "cause", None) or err
                outcome.error, outcome.attempts = f"{type(cause).__name__}: {cause}", 2
            outcomes.append(outcome)
            on_done(outcome)
    except KeyboardInterrupt as stop:
        signum = received.behind(stop)
        print(
            f"{signal.Signals(signum).name}: stopping; {len(pending)} runs save their"
            " checkpoints (again: at once)",
            file=sys.stderr,
        )
        for ref in pending:  # a running task gets a KeyboardInterrupt: it checkpoints
            ray.cancel(ref)
        # a second signal stops the wait at once (Ray's shutdown then ends the tasks)
        with contextlib.suppress(KeyboardInterrupt):
            ray.wait(list(pending), num_returns=len(pending), timeout=_STOP_WAIT_S)
        raise Interrupted(signum) from None
    return outcomes


def run_all(
    specs: Sequence[RunSpec],
    sweep_dir: Path,
    on_done: Callable[[Outcome], None],
    address: str | None = None,
    cpus_per_run: float = 1.0,
    sequential: bool = False,
    on_start: Callable[[RunSpec], None] | None = None,
) -> tuple[list[Outcome], bool]:
    """Run the specs on Ray when it is installed (and not ``sequential``), else one by one
    in this process (calling ``on_start`` as each begins), saying so; returns the
    outcomes and whether Ray ran them."""
    use_ray = not sequential
    if use_ray:
        try:
            with stop_signals("importing Ray"):  # cut short, it leaves Ray half-imported
                import ray  # noqa: F401
        except ImportError:
            use_ray = False
            print(
                'Ray is not installed (pip install -e ".[cluster]"): running sequentially',
                file=sys.stderr,
            )
    if use_ray:
        return run_on_ray(specs, sweep_dir, on_done, address, cpus_per_run), True
    return run_sequential(specs, sweep_dir, on_done, on_start), False
