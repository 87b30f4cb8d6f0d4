"""Sweeps of scenarios × algorithms × seeds, each run a Ray task (or sequential without Ray).

    python -m a2cm_phys.sweep --scenarios grid,grid_collision --algos a2c,a2cm --seeds 0-4

Each run is exactly ``python -m a2cm_phys.train`` with that scenario, algorithm and seed,
written to its own run directory ``<logdir>/<scenario>-<algo>-s<seed>/`` (config,
checkpoint, MCAP log, summary), so a sweep's numbers equal those of the runs done one by
one. Re-running a sweep skips finished runs and resumes unfinished ones from their
checkpoints, but only runs whose resolved scenario and training config are exactly the
requested ones: a run directory holding another configuration is an error naming the
difference, found before anything runs. A failing run is retried once and reported while the
others go on. Each run holds its run directory's lock
(:func:`a2cm_phys.training.rundir.run_lock`) while it runs: a run that another process
writes (a ``train``, or a second sweep on the same ``--logdir``) is reported busy and left
alone, so no run is ever written twice at once. Ctrl-C or SIGTERM stop the sweep cleanly:
running runs save their checkpoints, the exit status is 130 or 143, and the same command
resumes. Without ``--address`` Ray starts locally on this machine's cores; ``--address
auto`` or ``ray://host:10001`` uses an existing cluster. Without Ray installed (``pip
install -e ".[cluster]"``) the runs go one after another in this process."""

from __future__ import annotations

import contextlib
import csv
import fcntl
import io
import json
import os
import shlex
import signal
import sys
import threading
import traceback
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from ..analysis.stats import t_interval
from ..config import (
    ConfigError,
    Scenario,
    Train,
    load_scenario,
    load_train,
    resolve_train,
    stored_train,
    to_dict,
)
from ..training import checkpoint
from ..training.rundir import (
    CHECKPOINT_NAME,
    CONFIG_NAME,
    SUMMARY_NAME,
    RunBusy,
    read_config,
    remove_stray_temps,
    run_lock,
    write_atomic,
    write_config,
)
from ..training.trainer import Trainer

SUMMARY_CSV = "sweep_summary.csv"
"""The sweep's table (per scenario × algorithm), in ``--logdir``."""

SUMMARY_JSON = "sweep_summary.json"
"""The table and every run's outcome, in ``--logdir``."""

BUSY = "busy"
"""The outcome of a run that another process writes (it holds the run's lock)."""


class Interrupted(KeyboardInterrupt):
    """A stop signal (``signum``: SIGINT or SIGTERM) stopped the sweep; running runs have
    saved their checkpoints."""

    def __init__(self, signum: int = signal.SIGINT) -> None:
        super().__init__(signum)  # the args make it picklable (it may cross from a Ray task)
        self.signum = signum


@dataclass(frozen=True)
class RunSpec:
    """One training run of a sweep: scenario, algorithm, seed and shared options."""

    scenario: str
    algo: str
    seed: int
    train: dict[str, Any] = field(default_factory=dict)  # Train overrides shared by all runs
    overrides: dict[str, Any] = field(default_factory=dict)  # scenario overrides
    record: bool = True
    log_every: int = 1

    @property
    def name(self) -> str:
        """The run directory's name."""
        return f"{Path(self.scenario).stem}-{self.algo}-s{self.seed}"

    def resolve(self) -> tuple[Scenario, Train]:
        """The validated scenario and training config of this run."""
        scenario = load_scenario(self.scenario, self.overrides)
        cfg = load_train({**self.train, "algo": self.algo, "seed": self.seed})
        return scenario, resolve_train(scenario, cfg)

    def command(self, run_dir: Path) -> str:
        """The equivalent ``train`` command line (for the record)."""
        argv = [
            "python",
            "-m",
            "a2cm_phys.train",
            "--scenario",
            self.scenario,
            "--algo",
            self.algo,
            "--seed",
            str(self.seed),
            "--run-dir",
            str(run_dir),
        ]
        argv += [f"--set=train.{k}={v}" for k, v in self.train.items()]
        argv += [f"--set={k}={v}" for k, v in self.overrides.items()]
        return shlex.join(argv)


def run_state(run_dir: Path) -> str:
    """``done`` (summary of a finished run), ``partial`` (a checkpoint) or ``new``."""
    summary = run_dir / SUMMARY_NAME
    if summary.exists():
        try:
            if json.loads(summary.read_text()).get("status") == "done":
                return "done"
        except (OSError, json.JSONDecodeError):
            pass
    return "partial" if (run_dir / CHECKPOINT_NAME).exists() else "new"


def _plain(obj: Any) -> Any:
    return json.loads(json.dumps(to_dict(obj)))


def stored_config(run_dir: Path) -> dict[str, Any] | None:
    """The resolved ``scenario`` and ``train`` config a run directory holds (its
    ``config.json``, else its checkpoint), or ``None`` if it holds no run."""
    if (run_dir / CONFIG_NAME).exists():
        try:
            return read_config(run_dir)
        except ConfigError as err:
            raise ConfigError(f"{err}; cannot tell which run this is") from None
    if (run_dir / CHECKPOINT_NAME).exists():
        try:
            state = checkpoint.load(run_dir)
        except (OSError, ValueError) as err:
            raise ConfigError(str(err)) from None
        return {"scenario": state["scenario"], "train": state["train"]}
    return None


def differences(stored: Any, wanted: Any, prefix: str = "") -> list[str]:
    """``key: stored vs wanted`` for every leaf that differs between two nested dicts."""
    if isinstance(stored, dict) and isinstance(wanted, dict):
        out = []
        for key in sorted(set(stored) | set(wanted)):
            out += differences(stored.get(key), wanted.get(key), f"{prefix}{key}.")
        return out
    return [] if stored == wanted else [f"{prefix[:-1]}: {stored!r} there, {wanted!r} now"]


def check_reusable(spec: RunSpec, sweep_dir: Path) -> None:
    """A :class:`ConfigError` if ``spec``'s run directory holds a run of another resolved
    configuration (it would be reported as this run's result)."""
    run_dir = sweep_dir / spec.name
    stored = stored_config(run_dir)
    if stored is None:
        return
    scenario, cfg = spec.resolve()
    stored = {**stored, "train": stored_train(stored["train"])}
    diff = differences(stored, {"scenario": _plain(scenario), "train": _plain(cfg)})
    if diff:
        shown = "; ".join(diff[:3]) + (f"; and {len(diff) - 3} more" if len(diff) > 3 else "")
        raise ConfigError(
            f"{run_dir}: holds a run of another configuration ({shown}); use another --logdir,"
            " or move that run away"
        )


def execute(spec: RunSpec, sweep_dir: str) -> dict[str, Any]:
    """Run (or resume, or skip) one run holding its run directory's lock; returns its
    summary, with ``"sweep"`` saying what was done (``ran``, ``resumed``, ``skipped``), or
    ``{"sweep": "busy", "busy": why}`` if another process holds the lock. Runs inside a Ray
    task or in the sweep's process."""
    run_dir = Path(sweep_dir) / spec.name
    run_dir.mkdir(parents=True, exist_ok=True)
    with contextlib.ExitStack() as held:
        try:
            held.enter_context(run_lock(run_dir))
        except RunBusy as err:
            return {"sweep": BUSY, "busy": str(err)}
        # everything below, from reading the run's state on, happens under the lock
        return _execute_locked(spec, run_dir)


def _execute_locked(spec: RunSpec, run_dir: Path) -> dict[str, Any]:

    check_reusable(spec, run_dir.parent)
    state = run_state(run_dir)
    if state == "done":
        return {**json.loads((run_dir / SUMMARY_NAME).read_text()), "sweep": "skipped"}
    remove_stray_temps(run_dir)  # a writer killed mid-write left them; we hold the lock
    options = {"record": spec.record, "log_every": spec.log_every, "progress": False}
    if state == "partial":
        trainer = Trainer.resume(run_dir, **options)
    else:
        scenario, cfg = spec.resolve()
        write_config(run_dir, scenario, cfg, spec.command(run_dir))
        trainer = Trainer(scenario, cfg, run_dir, **options)
    try:
        status = trainer.run()
    finally:
        trainer.close()
    if status == "interrupted":  # Ctrl-C or SIGTERM: the checkpoint is saved, stop the sweep
        raise Interrupted(trainer.stop_signal or signal.SIGINT)
    if status != "done":
        raise RuntimeError(f"{spec.name}: training stopped ({status}) {trainer.stop_reason}")
    return {**trainer.last_summary, "sweep": "resumed" if state == "partial" else "ran"}


@dataclass
class Outcome:
    """What became of one run: its summary, the error it failed with, or why it was busy
    (another process writes it)."""

    spec: RunSpec
    summary: dict[str, Any] | None = None
    error: str | None = None
    attempts: int = 1
    busy: str | None = None

    @property
    def status(self) -> str:
        """``ran``, ``resumed``, ``skipped``, ``busy`` or ``failed``."""
        if self.busy is not None:
            return BUSY
        if self.error is not None or self.summary is None:
            return "failed"
        return str(self.summary.get("sweep", "ran"))

    def take(self, result: dict[str, Any]) -> None:
        """Record what :func:`execute` returned."""
        if result.get("sweep") == BUSY:
            self.summary, self.error, self.busy = None, None, str(result["busy"])
        else:
            self.summary, self.error, self.busy = result, None, None

    def describe(self) -> str:
        """The outcome in a few words, for the sweep's progress lines."""
        if self.busy is not None:
            return f"busy ({self.busy})"
        if self.error is not None:
            return f"FAILED ({self.error})"
        return self.status


@dataclass
class _Received:
    """The first stop signal :func:`_stop_signals` caught (``None``: none yet)."""

    signum: int | None = None

    def behind(self, stop: KeyboardInterrupt) -> int:
        """The signal that raised ``stop``: Ray turns an :class:`Interrupted` raised inside
        ``ray.wait`` into a bare ``KeyboardInterrupt``, so the handler's record counts too."""
        if isinstance(stop, Interrupted):
            return stop.signum
        return self.signum or signal.SIGINT


_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


@contextlib.contextmanager
def _stop_signals(wait: str | None = None) -> Iterator[_Received]:
    """For the block, SIGINT and SIGTERM raise :class:`Interrupted` (naming the signal) in
    the sweep's main thread; with ``wait`` (a message saying why), they are only noted, and
    the first raises at the end of the block. A trainer running in this process replaces
    the handlers while it runs (it stops after its update, with a checkpoint) and restores
    them. The handlers found are restored at the end, whoever replaced them meanwhile
    (``ray.init`` does)."""
    received = _Received()
    if threading.current_thread() is not threading.main_thread():
        yield received
        return

    def handle(signum: int, frame: Any) -> None:
        received.signum = received.signum or signum
        if wait is None:
            raise Interrupted(signum)
        print(f"{signal.Signals(signum).name}: {wait}, please wait", file=sys.stderr)

    previous = {s: signal.signal(s, handle) for s in _STOP_SIGNALS}
    try:
        yield received
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler if handler is not None else signal.SIG_DFL)
    if wait is not None and received.signum is not None:
        raise Interrupted(received.signum)


@contextlib.contextmanager
def _handlers_kept() -> Iterator[None]:
    """The SIGINT and SIGTERM handlers of the start of the block are back at its end."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.getsignal(s) for s in _STOP_SIGNALS}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler if handler is not None else signal.SIG_DFL)


def run_sequential(
    specs: Sequence[RunSpec], sweep_dir: Path, on_done: Callable[[Outcome], None]
) -> list[Outcome]:
    """Run the specs one by one in this process, retrying each failure once (a busy run is
    not retried); Ctrl-C or SIGTERM raise :class:`Interrupted` once the running run has saved
    its checkpoint."""
    outcomes = []
    with _stop_signals():
        for spec in specs:
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
    with _handlers_kept():
        try:
            if owned:
                _init_ray(ray, address)
            with _stop_signals() as received:
                return _wait_on_ray(ray, specs, sweep_dir, on_done, cpus_per_run, received)
        finally:
            if owned:
                with _stop_signals("shutting Ray down"):
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
    received: _Received,
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
) -> tuple[list[Outcome], bool]:
    """Run the specs on Ray when it is installed (and not ``sequential``), else one by one
    in this process, saying so; returns the outcomes and whether Ray ran them."""
    use_ray = not sequential
    if use_ray:
        try:
            with _stop_signals("importing Ray"):  # cut short, it leaves Ray half-imported
                import ray  # noqa: F401
        except ImportError:
            use_ray = False
            print(
                'Ray is not installed (pip install -e ".[cluster]"): running sequentially',
                file=sys.stderr,
            )
    if use_ray:
        return run_on_ray(specs, sweep_dir, on_done, address, cpus_per_run), True
    return run_sequential(specs, sweep_dir, on_done), False


def summarise(outcomes: Iterable[Outcome]) -> list[dict[str, Any]]:
    """Per scenario × algorithm: mean ± 95% CI (Student t across seeds) of episodes
    completed and final mean episode length."""
    groups: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for o in outcomes:
        if o.summary is not None:
            groups.setdefault((Path(o.spec.scenario).stem, o.spec.algo), []).append(o.summary)
    rows = []
    for (scenario, algo), runs in sorted(groups.items()):
        row: dict[str, Any] = {"scenario": scenario, "algo": algo, "seeds": len(runs)}
        for key in ("episodes", "mean_length_last_1000", "collisions_per_episode", "wall_time_s"):
            mean, half = t_interval([r[key] for r in runs])
            row[key], row[f"{key}_ci95"] = mean, half
        rows.append(row)
    return rows


def write_summary(
    rows: list[dict[str, Any]], outcomes: list[Outcome], sweep_dir: Path
) -> list[Path]:
    """Save the table as ``sweep_summary.csv`` (unless no run finished: then an older one is
    removed, it would describe another sweep) and, with every run's outcome,
    ``sweep_summary.json``, each atomically; returns the files written."""
    with _summary_lock(sweep_dir):
        return _write_summary(rows, outcomes, sweep_dir)


@contextlib.contextmanager
def _summary_lock(sweep_dir: Path) -> Iterator[None]:
    """Two sweeps of one ``--logdir`` write its summary files one after the other: their
    temp files share a name. Waits (the other's writes take milliseconds)."""
    fd = os.open(sweep_dir / ".sweep_summary.lock", os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # releases the lock


def _write_summary(
    rows: list[dict[str, Any]], outcomes: list[Outcome], sweep_dir: Path
) -> list[Path]:
    written = []
    csv_path = sweep_dir / SUMMARY_CSV
    if rows:
        text = io.StringIO()
        writer = csv.DictWriter(text, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
        write_atomic(csv_path, text.getvalue())
        written.append(csv_path)
    else:
        csv_path.unlink(missing_ok=True)
    runs = [
        {
            "run": o.spec.name,
            "outcome": o.status,
            "error": o.error,
            "busy": o.busy,
            "attempts": o.attempts,
            "summary": o.summary,
            "spec": asdict(o.spec),
        }
        for o in outcomes
    ]
    json_path = sweep_dir / SUMMARY_JSON
    write_atomic(json_path, json.dumps({"table": rows, "runs": runs}, indent=2, default=str) + "\n")
    written.append(json_path)
    return written


def format_table(rows: list[dict[str, Any]]) -> str:
    """The summary as a markdown table."""
    lines = [
        "| scenario | algo | seeds | episodes | mean length (last 1,000) |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['scenario']} | {r['algo']} | {r['seeds']} | {r['episodes']:,.0f} ± "
            f"{r['episodes_ci95']:,.0f} | {r['mean_length_last_1000']:.2f} ± "
            f"{r['mean_length_last_1000_ci95']:.2f} |"
        )
    return "\n".join(lines)
