"""The torch-free runtime (issue 34): :mod:`a2cm_phys.deploy` loads an exported team, acts in
the env's own formats, samples reproducibly, refuses damaged folders in one line, and runs
in an interpreter where torch and gymnasium cannot be imported; the pretrained teams come
with the package and play well."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import tomllib

pytest.importorskip("onnxruntime")

from a2cm_phys.config import load_scenario, load_train, resolve_train
from a2cm_phys.deploy import (
    POLICY_FILE,
    Actor,
    DeployError,
    Team,
    clip_to_box,
    clip_to_disc,
    load_team,
    pretrained_dir,
    pretrained_names,
    read_policy,
)
from a2cm_phys.deploy.pretrained import pretrained_root
from a2cm_phys.envs.parallel import make_env

PRETRAINED = ("grid_collision", "phys_cont")


def blocked(code: str, *modules: str) -> subprocess.CompletedProcess:
    """Run ``code`` in a fresh interpreter in which importing any of ``modules`` fails."""
    prelude = textwrap.dedent(
        f"""
        import sys
        class Block:
            def find_spec(self, name, path=None, target=None):
                if name.split(".")[0] in {modules!r}:
                    raise ImportError(f"{{name}} is blocked in this test")
        sys.meta_path.insert(0, Block())
        """
    )
    return subprocess.run(
        [sys.executable, "-c", prelude + textwrap.dedent(code)],
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_the_runtime_imports_and_runs_without_torch_or_gymnasium() -> None:
    proc = blocked(
        """
        import numpy as np
        from a2cm_phys.deploy import Team, pretrained_dir
        grid = Team.load(pretrained_dir("grid_collision"))
        obs = np.array([0, 0, 0, 1, 1, 0, 1, 1], dtype=np.float32) / 4
        print(grid.act({a: obs for a in grid.agents}))
        cont = Team.load(pretrained_dir("phys_cont"))
        print(cont.act(np.full((5, 16), 0.5, np.float32)).shape)
        heavy = ("torch", "gymnasium", "pymunk", "a2cm_phys.envs", "a2cm_phys.config")
        print(sorted(m for m in heavy if m in sys.modules))
        """,
        "torch",
        "gymnasium",
    )
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[0].startswith("{'pursuer_0': ") and lines[1] == "(5, 3, 2)", lines
    assert lines[2] == "[]"


def test_without_onnxruntime_the_error_names_the_extra() -> None:
    proc = blocked(
        """
        from a2cm_phys.deploy import DeployError, Team, pretrained_dir
        try:
            Team.load(pretrained_dir("grid_collision"))
        except DeployError as err:
            print(err)
        """,
        "onnxruntime",
    )
    assert proc.returncode == 0, proc.stderr
    assert "pip install 'a2cm_phys[deploy]'" in proc.stdout


@pytest.mark.parametrize("name", PRETRAINED)
def test_a_pretrained_team_plays_the_env_through_its_own_api(name: str) -> None:
    team = Team.load(pretrained_dir(name))
    env = make_env(team.scenario["name"])
    lengths = []
    for seed in range(20):
        obs, _ = env.reset(seed=seed)
        t = 0
        while env.agents:
            actions = team.act(obs)
            assert set(actions) == set(env.agents)
            obs, _, _, _, infos = env.step(actions)
            t += 1
        assert infos["pursuer_0"]["captured"], (name, seed)
        lengths.append(t)
    assert np.mean(lengths) < (6 if name == "grid_collision" else 40), lengths


def test_the_pretrained_teams_ship_small_and_documented() -> None:
    assert set(PRETRAINED) <= set(pretrained_names())
    files = {
        p for p in pretrained_root().rglob("*") if p.is_file() and "__pycache__" not in p.parts
    }
    assert sum(p.stat().st_size for p in files) <= 1_000_000
    package = pretrained_root().parent  # every file is package data, so wheels carry them
    pyproject = tomllib.loads((package.parent / "pyproject.toml").read_text(encoding="utf-8"))
    globs = pyproject["tool"]["setuptools"]["package-data"]["a2cm_phys"]
    assert files <= {p for g in globs for p in package.glob(g)}
    readme = (pretrained_root() / "README.md").read_text(encoding="utf-8")
    for name in PRETRAINED:
        policy = read_policy(pretrained_dir(name))
        assert policy["scenario"]["name"] == name and policy["network"]["algo"] == "a2cm"
        assert f"--scenario {name}" in readme
    with pytest.raises(DeployError, match=r"available: .*grid_collision.*phys_cont"):
        pretrained_dir("no_such_team")
    assert isinstance(load_team("pretrained:grid_collision"), Team)
    assert load_team("some/run/dir") is None


def test_one_actor_acts_on_one_observation_or_a_batch() -> None:
    actor = Actor.load(pretrained_dir("grid_collision") / "pursuer_0.onnx")
    obs = np.random.default_rng(0).integers(0, 5, size=(9, 8)) / 4
    batch = actor.act(obs)
    assert batch.shape == (9,) and batch.dtype == np.int64 and ((batch >= 0) & (batch < 4)).all()
    assert actor.act(obs[2]) == batch[2] and actor.act(obs[2]).shape == ()
    assert actor.outputs(obs)["logits"].shape == (9, 4)
    with pytest.raises(DeployError, match=r"shape \(9, 7\), expected \(8,\)"):
        actor.act(obs[:, :7])
    cont = Actor.load(pretrained_dir("phys_cont") / "pursuer_1.onnx")
    out = cont.outputs(np.full(16, 0.4, np.float32))
    assert set(out) == {"mean", "log_std"} and out["mean"].shape == (2,)
    far = cont.act(np.full((50, 16), 3.0, np.float32))  # outside the arena: long commands
    assert (np.linalg.norm(far, axis=-1) <= 1 + 1e-6).all()


def test_sampling_is_the_callers_generator_and_follows_the_softmax() -> None:
    team = Team.load(pretrained_dir("grid_collision"))
    obs = np.tile(np.array([0, 0, 0, 4, 4, 0, 2, 2], np.float32) / 4, (20_000, 1))
    a = team.act(obs, np.random.default_rng(1), greedy=False)
    b = team.act(obs, np.random.default_rng(1), greedy=False)
    c = team.act(obs, np.random.default_rng(2), greedy=False)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    logits = team.actors["pursuer_0"].outputs(obs[0])["logits"].astype(np.float64)
    probs = np.exp(logits - logits.max())
    probs /= probs.sum()
    freq = np.bincount(a[:, 0], minlength=4) / len(a)
    np.testing.assert_allclose(freq, probs, atol=0.015)
    cont = Team.load(pretrained_dir("phys_cont"))
    many = cont.act(np.full((500, 16), 0.5, np.float32), np.random.default_rng(0), greedy=False)
    assert many.shape == (500, 3, 2) and np.unique(many[:, 0, 0]).size == 500
    assert (np.linalg.norm(many, axis=-1) <= 1 + 1e-6).all()


def test_commands_are_limited_as_the_env_limits_them(tmp_path: Path) -> None:
    far = np.full((50, 16), 3.0, np.float32)  # outside the arena: long commands
    disc = Actor.load(pretrained_dir("phys_cont") / "pursuer_1.onnx")
    box = Actor.load(pretrained_dir("phys_cont") / "pursuer_1.onnx", clip=clip_to_box)
    mean = disc.outputs(far)["mean"]
    assert (np.abs(mean) > 1).any()
    np.testing.assert_array_equal(box.act(far), np.clip(mean, -1, 1))
    np.testing.assert_allclose(
        disc.act(far), mean / np.maximum(1, np.hypot(*mean.T))[:, None], atol=1e-6
    )
    folder = copy_of("phys_cont", tmp_path)  # what policy.json says picks the rule
    policy = json.loads((folder / POLICY_FILE).read_text())
    assert "drive" not in policy["actions"] and Team.load(folder).clip is clip_to_disc
    policy["actions"]["drive"] = "differential"
    (folder / POLICY_FILE).write_text(json.dumps(policy))
    team = Team.load(folder)
    assert team.clip is clip_to_box and team.actors["pursuer_1"].clip is clip_to_box
    policy["actions"]["drive"] = "tracked"
    (folder / POLICY_FILE).write_text(json.dumps(policy))
    with pytest.raises(DeployError, match=r"actions\.drive 'tracked'"):
        Team.load(folder)


def copy_of(name: str, tmp_path: Path) -> Path:
    """A copy of a pretrained team to damage."""
    return Path(shutil.copytree(pretrained_dir(name), tmp_path / name))


def test_a_damaged_folder_is_one_error_naming_the_file(tmp_path: Path) -> None:
    with pytest.raises(DeployError, match="not a folder"):
        Team.load(tmp_path / "missing")
    with pytest.raises(DeployError, match=re.escape("no policy.json")):
        Team.load(tmp_path)
    folder = copy_of("grid_collision", tmp_path)
    raw = bytearray((folder / "pursuer_1.onnx").read_bytes())
    raw[-5] ^= 1
    (folder / "pursuer_1.onnx").write_bytes(bytes(raw))
    with pytest.raises(DeployError, match=re.escape("pursuer_1.onnx: changed since export")):
        Team.load(folder)
    (folder / "pursuer_1.onnx").unlink()
    with pytest.raises(DeployError, match=re.escape("pursuer_1.onnx: missing")):
        Team.load(folder)
    policy = json.loads((folder / POLICY_FILE).read_text())
    (folder / POLICY_FILE).write_text(json.dumps({**policy, "format": "other/9"}))
    with pytest.raises(DeployError, match="format 'other/9', this runtime reads"):
        read_policy(folder)
    del policy["greedy"]
    (folder / POLICY_FILE).write_text(json.dumps(policy))
    with pytest.raises(DeployError, match=re.escape("policy.json: missing greedy")):
        read_policy(folder)
    (folder / POLICY_FILE).write_text("{not json")
    with pytest.raises(DeployError, match="unreadable"):
        read_policy(folder)


@pytest.fixture(scope="module")
def selfplay_team(tmp_path_factory: pytest.TempPathFactory) -> Team:
    """An exported tiny self-play run (pursuers and a learned evader)."""
    from a2cm_phys.training.export import export_run
    from a2cm_phys.training.trainer import Trainer

    run = tmp_path_factory.mktemp("vs")
    scenario = load_scenario("grid_vs")
    cfg = resolve_train(scenario, load_train({"num_envs": 4, "updates": 5}))
    assert Trainer(scenario, cfg, run, record=False).run() == "done"
    export_run(run, run / "onnx", check=100)
    return Team.load(run / "onnx")


def test_a_team_with_a_learned_evader_acts_for_every_agent(selfplay_team: Team) -> None:
    team = selfplay_team
    assert team.agents == ["pursuer_0", "pursuer_1", "pursuer_2", "evader"]
    env = make_env("grid_vs", max_steps=30)
    obs, _ = env.reset(seed=3)
    while env.agents:
        actions = team.act(obs, np.random.default_rng(0), greedy=False)
        assert set(actions) == set(env.agents) and all(type(a) is int for a in actions.values())
        obs, *_ = env.step(actions)
    evader = team.rollout_policy(side="evader")(np.zeros((6, 8), np.float32), None)
    assert evader.shape == (6, 1)
    plain = Team.load(pretrained_dir("grid_collision"))
    with pytest.raises(DeployError, match="no learned evader"):
        plain.rollout_policy(side="evader")
