"""Export to ONNX (issue 34): the exported actors give the run's own outputs and greedy
actions on observations from real episodes, for A2C and A2CM, discrete and continuous; a
discrete team plays the same seeded episodes move for move; ``policy.json`` says what a
user needs; the command's errors are one line, exit 2."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("onnx")
pytest.importorskip("onnxruntime")

import onnx

from a2cm_phys.analysis.evaluation import play
from a2cm_phys.analysis.stats import mean_and_se
from a2cm_phys.commands.export import main
from a2cm_phys.config import Scenario, build, load_scenario, load_train, resolve_train
from a2cm_phys.deploy import POLICY_FILE, Team, clip_to_box, clip_to_disc, read_policy
from a2cm_phys.deploy.spec import REQUIRED
from a2cm_phys.envs.parallel import make_env
from a2cm_phys.envs.vector import VectorEnv
from a2cm_phys.training.export import TOLERANCE, export_run, parity
from a2cm_phys.training.runs import TrainedRun, load_trained_run, model_policy
from a2cm_phys.training.trainer import Trainer

RUNS = {
    "grid-a2cm": ("grid_collision", {"algo": "a2cm"}),
    "grid-a2c-onehot": ("grid_collision", {"algo": "a2c", "encoding": "onehot", "layers": 2}),
    "phys-a2cm": ("phys_cont", {"algo": "a2cm"}),
    "phys-a2c": ("phys_cont", {"algo": "a2c", "layers": 2}),
    "grid-vs-a2cm": ("grid_vs", {"algo": "a2cm", "encoding": "onehot"}),
    "diff-a2cm": ("phys_diff", {"algo": "a2cm"}),
    "phys-a2cm-relative": ("phys_cont_random", {"algo": "a2cm", "encoding": "relative"}),
    "grid-vs-a2c-relative": ("grid_vs", {"algo": "a2c", "encoding": "relative"}),
    "phys-a2cm-metric": ("phys_cont10_random", {"algo": "a2cm", "encoding": "metric"}),
}
"""Tiny runs: both learners, both control types, one-hot cells, deeper actors, a learned
evader, differential drive, relative and metric inputs (folded into the first layers)."""


def train(path: Path, scenario_name: str, values: dict) -> Path:
    """A short run in ``path`` (a checkpoint to export)."""
    scenario = load_scenario(scenario_name)
    updates = 20 if scenario.mode == "grid" else 6
    cfg = load_train({"num_envs": 8, "updates": updates, "seed": 3, **values})
    assert Trainer(scenario, resolve_train(scenario, cfg), path, record=False).run() == "done"
    return path


@pytest.fixture(scope="module", params=list(RUNS))
def exported(request, tmp_path_factory) -> tuple[TrainedRun, Team, Path]:
    """A tiny run of :data:`RUNS`, exported: (the run's models, the team, the run)."""
    scenario_name, values = RUNS[request.param]
    run = train(tmp_path_factory.mktemp(request.param), scenario_name, values)
    done = export_run(run, run / "onnx")
    assert done.parity.ok, done.parity
    return load_trained_run(run), Team.load(run / "onnx"), run


def episode_observations(trained: TrainedRun, n: int, seed: int = 0) -> np.ndarray:
    """``n`` observations from real episodes: the run's actors playing, sampled."""
    scenario = trained.scenario
    env = VectorEnv(scenario, 16)
    obs, rng, seen = env.reset(seed), np.random.default_rng(seed), []
    while sum(len(o) for o in seen) < n:
        seen.append(obs.copy())
        actions = trained.pursuers.act(obs, rng)
        evader = None if trained.evader is None else trained.evader.act(obs, rng)[:, 0]
        obs = env.step(actions, evader, validate=False).obs
    env.close()
    return np.concatenate(seen)[:n]


def test_exported_actors_match_the_runs_on_real_observations(exported) -> None:
    trained, team, _ = exported
    obs = episode_observations(trained, 10_000)
    result = parity(trained, team, obs)
    assert result.observations == 10_000
    assert result.max_abs_diff <= TOLERANCE, result
    assert result.agreement == 1.0 and result.ok, result
    n = trained.scenario.pursuers
    assert len(team.actors) == (n + 1 if trained.evader is not None else n)
    assert ("evader" in team.actors) == (trained.evader is not None)


def test_parity_notices_a_different_actor(exported, tmp_path) -> None:
    """The check can fail: another run's actors (other weights) are told apart."""
    trained, team, _ = exported
    other = {**team.actors}
    first, second = team.pursuers[:2] if len(team.pursuers) > 1 else (team.pursuers[0],) * 2
    other[first], other[second] = team.actors[second], team.actors[first]
    swapped = Team(other, team.policy)
    result = parity(trained, swapped, episode_observations(trained, 500))
    assert not result.ok and result.max_abs_diff > 1e-3, result


def test_a_discrete_team_plays_the_runs_episodes_move_for_move(exported) -> None:
    trained, team, _ = exported
    scenario = trained.scenario
    if scenario.continuous:
        pytest.skip("discrete control")
    learned = trained.evader is not None
    torch_evader = model_policy(trained.evader, greedy=True) if learned else None
    onnx_evader = team.rollout_policy(greedy=True, side="evader") if learned else None
    torch_policy = model_policy(trained.pursuers, greedy=True)
    torch_play = play(scenario, torch_policy, 60, 8, seed=11, evader=torch_evader)
    onnx_play = play(scenario, team.rollout_policy(greedy=True), 60, 8, seed=11, evader=onnx_evader)
    np.testing.assert_array_equal(torch_play.lengths, onnx_play.lengths)
    np.testing.assert_array_equal(torch_play.returns, onnx_play.returns)
    np.testing.assert_array_equal(torch_play.collisions, onnx_play.collisions)
    env = make_env(scenario)  # and through the env's own API, agent by agent
    for seed in range(5):
        trace = []
        for actor in ("torch", "onnx"):
            obs, _ = env.reset(seed=seed)
            steps = []
            while env.agents:
                if actor == "onnx":
                    actions = team.act(obs)
                else:
                    moves = trained.pursuers.act(env.state(), None, greedy=True)
                    actions = {a: int(m) for a, m in zip(scenario.agents, moves, strict=True)}
                    if learned:
                        actions["evader"] = int(trained.evader.act(env.state(), None, True)[0])
                steps.append(actions)
                obs, *_ = env.step(actions)
            trace.append(steps)
        assert trace[0] == trace[1] and trace[0]


def test_a_continuous_team_captures_alike(exported) -> None:
    trained, team, _ = exported
    scenario = trained.scenario
    if not scenario.continuous:
        pytest.skip("continuous control")
    episodes = 24
    a = play(scenario, model_policy(trained.pursuers, greedy=True), episodes, 8, seed=5)
    b = play(scenario, team.rollout_policy(greedy=True), episodes, 8, seed=5)
    for x, y in ((a.lengths, b.lengths), (a.captured, b.captured)):
        (ma, sa), (mb, sb) = mean_and_se(x), mean_and_se(y)
        half = 1.96 * np.hypot(np.nan_to_num(sa), np.nan_to_num(sb))
        assert abs(ma - mb) <= half + 1e-9, (ma, mb, half)


def test_a_differential_team_drives_the_env_through_its_own_api(exported) -> None:
    trained, team, _ = exported
    scenario = trained.scenario
    if not scenario.differential:
        pytest.skip("differential drive")
    obs = episode_observations(trained, 256)
    actions = team.act(obs)  # (forward, turn) clipped to the box, as the env clips them
    for i, agent in enumerate(team.pursuers):
        mean = team.actors[agent].outputs(obs)["mean"]
        np.testing.assert_array_equal(actions[:, i], np.clip(mean, -1.0, 1.0))
    env = make_env(team.scenario["name"])
    obs, _ = env.reset(seed=4)
    steps = 0
    while env.agents:
        moves = team.act(obs)
        theirs = np.clip(trained.pursuers.act(env.state(), None, greedy=True), -1.0, 1.0)
        mine = np.stack([moves[a] for a in scenario.agents])
        np.testing.assert_allclose(mine, theirs, atol=TOLERANCE)
        obs, *_ = env.step(moves)
        steps += 1
    assert 0 < steps <= scenario.max_steps


def test_policy_json_round_trips_and_names_what_a_user_needs(exported) -> None:
    trained, team, run = exported
    folder = run / "onnx"
    text = (folder / POLICY_FILE).read_text(encoding="utf-8")
    policy = read_policy(folder)
    assert json.loads(json.dumps(policy)) == policy == json.loads(text)
    assert set(REQUIRED) <= set(policy)
    scenario = trained.scenario
    assert build(Scenario, policy["scenario"], "policy.json") == scenario
    obs = policy["observation"]
    assert obs["size"] == scenario.obs_dim == len(obs["layout"]) == len(obs["divided_by"])
    velocities = obs["layout"][: scenario.obs_dim - 2 * scenario.pursuers * scenario.differential]
    assert velocities[-2:] == (
        ["evader.x", "evader.y"] if scenario.mode == "grid" else ["evader.vx", "evader.vy"]
    )
    relative = trained.pursuers.relative
    kind = "relative" if relative is not None and relative.scale == 1.0 else "metric"
    assert obs["encoding"]["kind"] == (
        "onehot" if trained.pursuers.encoding else "xy" if relative is None else kind
    )
    assert team.arena_bound == trained.pursuers.arena_bound
    if kind == "metric" and relative is not None:
        assert obs["encoding"]["scale"] == relative.scale == scenario.size
    actions = policy["actions"]
    if scenario.differential:  # (forward, turn), and the headings after the velocities
        assert actions["drive"] == "differential" and team.clip is clip_to_box
        assert actions["max_turn_rate"] == scenario.physics.max_turn_rate
        assert "[-1, 1]" in policy["greedy"]
        headings = [f"{a}.{c}" for a in scenario.agents for c in ("cos", "sin")]
        assert obs["layout"][-len(headings) :] == headings
    elif scenario.continuous:
        assert "drive" not in actions and team.clip is clip_to_disc
        assert "unit circle" in policy["greedy"]
    if scenario.continuous:
        assert actions["max_speed"] == scenario.physics.max_speed
        assert actions["dt"] == scenario.physics.dt
    else:
        assert actions["meanings"][:2] == ["up (+y)", "down (-y)"]
        assert len(actions["meanings"]) == actions["count"] == scenario.actions
        assert policy["greedy"] == "argmax of the logits"
    assert policy["run"]["algo"] == ("a2c" if trained.pursuers.n_critics > 1 else "a2cm")
    assert policy["run"]["update"] > 0 and policy["package_version"]
    spec = policy["onnx"]
    for entry in policy["actors"]:  # the tensors policy.json names are the graphs'
        model = onnx.load(folder / entry["file"])
        assert model.opset_import[0].version == spec["opset"]
        (inp,) = model.graph.input
        assert inp.name == spec["input"]["name"]
        dims = inp.type.tensor_type.shape.dim
        assert (dims[0].dim_param, dims[1].dim_value) == ("batch", scenario.obs_dim)
        assert [o.name for o in model.graph.output] == [o["name"] for o in spec["outputs"]]
    assert [a["agent"] for a in policy["actors"]] == team.agents


def test_a_batch_of_any_size_and_one_observation(exported) -> None:
    trained, team, _ = exported
    obs = episode_observations(trained, 7)
    batch = team.act(obs)
    n = trained.scenario.pursuers
    assert batch.shape == ((7, n, 2) if team.continuous else (7, n))
    one = team.act(obs[3])
    np.testing.assert_array_equal(one, batch[3])


def run_cli(*args: str) -> subprocess.CompletedProcess:
    """``python -m a2cm_phys.export ARGS`` in a fresh interpreter."""
    cmd = [sys.executable, "-m", "a2cm_phys.export", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=300)


def test_a_bad_run_is_one_line_and_exit_2(tmp_path: Path, capsys) -> None:
    assert main([str(tmp_path / "missing")]) == 2
    (tmp_path / "checkpoint.pt").write_bytes(b"not a checkpoint")
    assert main([str(tmp_path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 2 and all(line.startswith("error: ") for line in err.splitlines())
    assert not (tmp_path / "out").exists()
    proc = run_cli(str(tmp_path / "missing"))
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr


def test_the_command_exports_and_refuses_a_foreign_folder(exported, tmp_path, capsys) -> None:
    _, _, run = exported
    out = tmp_path / "team"
    assert main([str(run), "--out", str(out), "--check", "50"]) == 0
    assert "greedy actions agree 100.00%" in capsys.readouterr().out
    assert main([str(run), "--out", str(out), "--check", "50"]) == 0  # an earlier export
    assert sorted(p.name for p in out.iterdir()) == sorted(
        [POLICY_FILE, *(f"{a}.onnx" for a in Team.load(out).agents)]
    )
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "notes.txt").write_text("mine")
    assert main([str(run), "--out", str(tmp_path / "other")]) == 2
    assert "not an earlier export" in capsys.readouterr().err
    assert (tmp_path / "other" / "notes.txt").read_text() == "mine"


def test_without_onnx_the_error_names_the_extra(exported, tmp_path, monkeypatch, capsys) -> None:
    _, _, run = exported
    monkeypatch.setitem(sys.modules, "onnx", None)  # import onnx raises ImportError
    assert main([str(run), "--out", str(tmp_path / "out")]) == 2
    assert "pip install 'a2cm_phys[deploy]'" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_help_is_fast_and_imports_no_torch() -> None:
    start = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-X", "importtime", "-m", "a2cm_phys.export", "--help"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 0 and "--out" in proc.stdout
    assert time.perf_counter() - start < 5  # the 1 s budget, with room for a busy machine
    imported = {line.split("|")[-1].strip() for line in proc.stderr.splitlines()}
    assert not {"torch", "onnx", "onnxruntime"} & imported
