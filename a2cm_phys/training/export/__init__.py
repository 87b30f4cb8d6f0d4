"""A trained run's actors exported to ONNX (``python -m a2cm_phys.export``): one model per
actor (:mod:`.graph`), ``policy.json`` beside them (:mod:`.describe`), and the exported team
checked against the run's own actors (:mod:`.parity`) before the export is called done.

The folder is then played by :mod:`a2cm_phys.deploy`, without torch.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from ...config import ConfigError, stored_train
from ...deploy import Team
from ...deploy.spec import POLICY_FILE, DeployError, sha256
from ..checkpoint import checkpoint_path
from ..checkpoint import load as load_checkpoint
from ..rundir import write_atomic
from ..runs import load_trained_run, run_identity
from .describe import policy_document
from .graph import OPSET, ActorWeights, actor_model, onnx_module
from .parity import TOLERANCE, Parity, parity, sample_observations

if TYPE_CHECKING:
    from ...algos import ActorCritic

__all__ = ["OPSET", "TOLERANCE", "Exported", "Parity", "actor_weights", "export_run", "parity"]


@dataclass(frozen=True)
class Exported:
    """What :func:`export_run` wrote: the folder, its files and their total size, and the
    exported team's :class:`Parity` with the run's actors."""

    folder: Path
    files: list[Path]
    parity: Parity

    @property
    def size(self) -> int:
        """Bytes of every file written."""
        return sum(f.stat().st_size for f in self.files)


def actor_weights(model: ActorCritic, agent: int) -> ActorWeights:
    """Agent ``agent``'s actor of ``model`` as numpy float32 (first layer, deeper hidden
    layers, output layer; ``log_std`` for a Gaussian). Relative inputs are folded into the
    first layer (``W M``, :class:`~a2cm_phys.algos.encoding.RelativePositions`): the
    exported actor reads the global observation."""
    stack = [model.actor_hidden, *model.actor_deep, model.actor_out]
    layers = [
        (layer.weight[agent].detach().cpu().numpy(), layer.bias[agent].detach().cpu().numpy())
        for layer in stack
    ]
    if model.relative is not None:
        weight, bias = layers[0]
        layers[0] = (weight @ model.relative.matrices[agent], bias)
    log_std = None if model.log_std is None else model.log_std[agent].detach().cpu().numpy()
    return ActorWeights(layers, log_std)


def prepare_folder(out: Path) -> None:
    """Make ``out`` ready to receive an export: new, empty, or an earlier export (whose
    files are removed); a :class:`DeployError` if it holds anything else or is a file."""
    if out.exists() and not out.is_dir():
        raise DeployError(f"--out {out}: is a file, expected a folder")
    if not out.exists():
        out.mkdir(parents=True)
        return
    if not any(out.iterdir()):
        return
    old = out / POLICY_FILE
    try:
        listed = [a["file"] for a in json.loads(old.read_text(encoding="utf-8"))["actors"]]
    except (OSError, ValueError, KeyError, TypeError):
        raise DeployError(
            f"--out {out}: not empty and not an earlier export; give a new or empty folder"
        ) from None
    for name in [POLICY_FILE, *listed]:
        if "/" not in name and "\\" not in name:  # only files of the folder itself
            (out / name).unlink(missing_ok=True)


def export_run(run: str | Path, out: str | Path, check: int = 1000, seed: int = 0) -> Exported:
    """Export the actors of the run directory (or checkpoint file) ``run`` into ``out``
    and check the exported team against them on ``check`` observations spread over what
    the env gives (:func:`~.parity.sample_observations` with ``seed``). A
    :class:`~a2cm_phys.config.ConfigError` if ``run`` is not a run, a
    :class:`DeployError` if ``out`` cannot take the export, onnx is missing, or the
    exported actors differ from the run's by more than :data:`TOLERANCE`."""
    onnx_module()  # before anything is read or written
    trained = load_trained_run(run)
    identity = run_identity(run)
    state = load_checkpoint(run)
    scenario, cfg = trained.scenario, stored_train(state["train"])
    if scenario.sensing.on:  # each actor reads its own masked vector: not exported yet
        raise ConfigError(
            f"{run}: a run of a sensing scenario ({scenario.name}, sensing.radius ="
            f" {scenario.sensing.radius:g}) cannot be exported yet; only full-observation"
            " runs can"
        )
    if trained.pursuers.recurrent:  # an actor's memory would be an input and an output
        raise ConfigError(
            f"{run}: a run with recurrent actors (recurrent = '{cfg['recurrent']}') cannot be"
            " exported yet; only memoryless actors can"
        )
    run = Path(run)
    folder = run if run.is_dir() else run.parent
    out = Path(out)
    prepare_folder(out)
    models = [(a, trained.pursuers, i) for i, a in enumerate(scenario.agents)]
    if trained.evader is not None:
        models.append(("evader", trained.evader, 0))
    actors, files = [], []
    for agent, model, i in models:
        doc = f"{agent}'s actor of run {folder.name} ({identity.label}, {scenario.name})"
        cells = None if model.encoding is None else model.encoding.size
        graph = actor_model(actor_weights(model, i), scenario.obs_dim, cells, agent, doc)
        file = out / f"{agent}.onnx"
        write_atomic(file, graph.SerializeToString())
        actors.append({"agent": agent, "file": file.name, "sha256": sha256(file)})
        files.append(file)
    source = {
        "name": folder.resolve().name,
        "path": str(run),
        "algo": identity.algo,
        "preset": identity.preset,
        "update": int(state["update"]),
        "seed": cfg.get("seed"),
        "checkpoint_sha256": sha256(checkpoint_path(run)),
    }
    document = policy_document(scenario, cfg, source, actors)
    write_atomic(out / POLICY_FILE, json.dumps(document, indent=2, ensure_ascii=False) + "\n")
    files.append(out / POLICY_FILE)
    result = parity(trained, Team.load(out), sample_observations(scenario, check, seed))
    if not result.ok:  # leave no folder that looks like a good export
        for file in files:
            file.unlink(missing_ok=True)
        raise DeployError(f"{out}: the exported actors differ from the run's ({result})")
    return Exported(out, files, result)
