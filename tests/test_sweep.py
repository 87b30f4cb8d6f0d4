"""Sweeps: Ray and sequential runs equal single train commands; failures are retried and
reported; a second invocation skips what is done."""

from __future__ import annotations

import json

import pytest

from a2cm_phys.commands import sweep
from a2cm_phys.commands.train import main as train_main
from a2cm_phys.study import launch
from a2cm_phys.study.launch import run_sequential
from a2cm_phys.study.runspec import RunSpec

TINY = {"updates": 4, "num_envs": 4, "batch_size": 16}
KEYS = ("episodes", "mean_length_last_1000", "collisions", "steps")


def specs(**train):
    return [
        RunSpec("grid", algo, seed, {**TINY, **train}, record=False)
        for algo in ("a2c", "a2cm")
        for seed in (0, 1)
    ]


def single_run(tmp_path, spec):
    run_dir = tmp_path / "single" / spec.name
    argv = [
        "--scenario",
        spec.scenario,
        "--algo",
        spec.algo,
        "--seed",
        str(spec.seed),
        "--run-dir",
        str(run_dir),
        "--no-record",
        "--no-progress",
    ]
    argv += [f"--set=train.{k}={v}" for k, v in spec.train.items()]
    assert train_main(argv) == 0
    return json.loads((run_dir / "summary.json").read_text())


def same(a, b):
    return all(a[k] == b[k] for k in KEYS)


def test_sequential_sweep_equals_single_runs_and_skips_on_rerun(tmp_path):
    plan = specs()
    seen = []
    outcomes = run_sequential(plan, tmp_path / "sweep", seen.append)
    assert [o.error for o in outcomes] == [None] * 4 and len(seen) == 4
    for o in outcomes:
        assert same(o.summary, single_run(tmp_path, o.spec))
    again = run_sequential(plan, tmp_path / "sweep", lambda o: None)
    assert {o.summary["sweep"] for o in again} == {"skipped"}


def test_failing_run_is_retried_and_reported_while_others_finish(tmp_path):
    plan = specs()
    plan[1] = RunSpec("grid", "a2c", 1, {**TINY, "reward_scale": 1e300}, record=False)
    outcomes = run_sequential(plan, tmp_path, lambda o: None)
    failed = [o for o in outcomes if o.error]
    assert [o.spec.name for o in failed] == [plan[1].name]
    assert failed[0].attempts == 2 and "nonfinite" in failed[0].error
    assert all(o.summary["status"] == "done" for o in outcomes if not o.error)


def test_an_interrupted_run_is_resumed_not_restarted(tmp_path, monkeypatch):
    from a2cm_phys.training.trainer import Trainer

    spec = specs()[0]
    original = Trainer._one_update

    def interrupt_at_update_2(self, on_step):
        if self.update == 2:
            raise KeyboardInterrupt
        original(self, on_step)

    monkeypatch.setattr(Trainer, "_one_update", interrupt_at_update_2)
    argv = [
        "--scenario",
        "grid",
        "--algo",
        spec.algo,
        "--seed",
        "0",
        "--no-record",
        "--run-dir",
        str(tmp_path / spec.name),
        "--no-progress",
    ]
    argv += [f"--set=train.{k}={v}" for k, v in TINY.items()]
    assert train_main(argv) == 130
    monkeypatch.setattr(Trainer, "_one_update", original)
    (outcome,) = run_sequential([spec], tmp_path, lambda o: None)
    assert outcome.summary["sweep"] == "resumed" and outcome.summary["updates"] == TINY["updates"]
    assert same(outcome.summary, single_run(tmp_path, spec))


def test_cli_summary_table_and_bad_seeds(tmp_path, capsys):
    args = [
        "--scenarios",
        "grid",
        "--algos",
        "a2c,a2cm",
        "--seeds",
        "0-1",
        "--sequential",
        "--sweep-dir",
        str(tmp_path),
        "--no-record",
    ]
    args += [f"--set=train.{k}={v}" for k, v in TINY.items()]
    assert sweep.main(args) == 0
    out = capsys.readouterr().out
    assert "| grid | a2c | 2 |" in out and "| grid | a2cm | 2 |" in out
    assert (tmp_path / "sweep_summary.csv").read_text().count("\n") == 3
    assert sweep.main(["--scenarios", "grid", "--seeds", "x-y"]) == 2
    assert "--seeds" in capsys.readouterr().err


@pytest.fixture(scope="module")
def local_ray():
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield ray
    ray.shutdown()


@pytest.mark.slow
def test_ray_sweep_equals_sequential_retries_failures_and_skips(tmp_path, local_ray):
    plan = specs()
    plan.append(RunSpec("grid", "a2cm", 9, {**TINY, "reward_scale": 1e300}, record=False))
    outcomes = launch.run_on_ray(plan, tmp_path / "ray", lambda o: None, None, 1.0)
    by_name = {o.spec.name: o for o in outcomes}
    assert by_name[plan[-1].name].error and "nonfinite" in by_name[plan[-1].name].error
    reference = run_sequential(plan[:-1], tmp_path / "seq", lambda o: None)
    for ref in reference:
        assert same(by_name[ref.spec.name].summary, ref.summary)
    again = launch.run_on_ray(plan[:-1], tmp_path / "ray", lambda o: None, None, 1.0)
    assert {o.summary["sweep"] for o in again} == {"skipped"}


def _sweep(tmp_path, *extra):
    args = ["--scenarios", "grid", "--algos", "a2cm", "--seeds", "0", "--sequential",
            "--logdir", str(tmp_path / "sweep"), "--no-record"]  # fmt: skip
    args += [f"--set=train.{k}={v}" for k, v in TINY.items()]
    return sweep.main([*args, *extra])


def test_a_run_of_other_settings_is_not_reused(tmp_path, capsys):
    assert _sweep(tmp_path) == 0
    capsys.readouterr()
    assert _sweep(tmp_path, "--set", "train.updates=10", "--set", "rewards.step=-7") == 2
    err = capsys.readouterr().err
    assert "another configuration" in err and "train.updates: 4 there, 10 now" in err
    assert "scenario.rewards.step: -1.0 there, -7.0 now" in err and err.count("\n") == 1
    assert _sweep(tmp_path) == 0  # the same settings: reused
    assert "grid-a2cm-s0: skipped" in "".join(capsys.readouterr())


def test_a_different_scenario_file_with_the_same_stem_is_not_reused(tmp_path, capsys):
    assert _sweep(tmp_path) == 0
    other = tmp_path / "other" / "grid.toml"
    other.parent.mkdir()
    other.write_text('mode = "grid"\nsize = 4\n')
    capsys.readouterr()
    args = ["--scenarios", str(other), "--algos", "a2cm", "--seeds", "0", "--sequential",
            "--logdir", str(tmp_path / "sweep"), "--no-record"]  # fmt: skip
    args += [f"--set=train.{k}={v}" for k, v in TINY.items()]
    assert sweep.main(args) == 2
    assert "scenario.size: 5 there, 4 now" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("seeds", "message"),
    [("0,0,1", "seed 0 is given twice"), ("0-2,1", "seed 1 is given twice"),
     ("0-99999999999", "too many seeds"), ("18446744073709551616", "beyond 64 bits")],
)  # fmt: skip
def test_bad_or_duplicate_seeds_exit_2(tmp_path, capsys, seeds, message):
    assert sweep.main(["--scenarios", "grid", "--seeds", seeds, "--logdir", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not any(tmp_path.iterdir())


def test_sweep_dir_is_an_alias_of_logdir(tmp_path, capsys):
    args = ["--scenarios", "grid", "--algos", "a2cm", "--seeds", "0", "--sequential",
            "--sweep-dir", str(tmp_path / "old"), "--no-record"]  # fmt: skip
    args += [f"--set=train.{k}={v}" for k, v in TINY.items()]
    assert sweep.main(args) == 0
    assert (tmp_path / "old" / "grid-a2cm-s0" / "summary.json").exists()


def test_an_interrupt_stops_the_sweep_instead_of_retrying(tmp_path, monkeypatch, capsys):
    from a2cm_phys.training.trainer import Trainer

    original, calls = Trainer._one_update, []

    def interrupt_at_update_2(self, on_step):
        calls.append(self.update)
        if self.update == 2:
            raise KeyboardInterrupt
        original(self, on_step)

    monkeypatch.setattr(Trainer, "_one_update", interrupt_at_update_2)
    assert _sweep(tmp_path, "--seeds", "0-1") == 130
    assert calls == [0, 1, 2]  # neither retried nor the next run started
    assert "run the same command to resume" in capsys.readouterr().err


def test_a_sweep_without_a_terminal_says_which_run_goes_on_every_interval(
    tmp_path, monkeypatch, capsys
):
    import time

    from a2cm_phys.training.trainer import Trainer

    original = Trainer._one_update

    def slow(self, on_step):
        time.sleep(0.15)
        original(self, on_step)

    monkeypatch.setattr(Trainer, "_one_update", slow)
    monkeypatch.setenv("A2CM_PROGRESS_SECONDS", "0.2")
    assert _sweep(tmp_path) == 0
    captured = capsys.readouterr()
    assert "grid-a2cm-s0: ran" in captured.out  # the run's fate: the result, on stdout
    lines = captured.err.splitlines()
    assert lines[0] == "sweep: started (1 runs)" and lines[-1].startswith("sweep: done, 1/1 runs")
    assert any(line.startswith("sweep: 0/1 runs (0%)") and "now grid-a2cm-s0" in line
               for line in lines[1:-1]), lines  # fmt: skip


def test_a_run_written_before_a_scenario_key_existed_is_still_this_run(tmp_path, capsys):
    """A run whose ``config.json`` predates a scenario key (here ``start``, added with
    random starts) holds that key's default: the sweep skips it as done, as it skips
    training keys added since, instead of calling it another configuration."""
    assert _sweep(tmp_path) == 0
    path = tmp_path / "sweep" / "grid-a2cm-s0" / "config.json"
    config = json.loads(path.read_text())
    assert config["scenario"].pop("start")["kind"] == "fixed"
    path.write_text(json.dumps(config))
    capsys.readouterr()
    assert _sweep(tmp_path) == 0
    assert "grid-a2cm-s0: skipped" in "".join(capsys.readouterr())
    assert _sweep(tmp_path, "--set", "start=random") == 2  # the default, not any start
    assert "scenario.start.kind: 'fixed' there, 'random' now" in capsys.readouterr().err
