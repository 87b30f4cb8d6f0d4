"""Running a trained team without torch: numpy and onnxruntime only (``pip install
'a2cm_phys[deploy]'``).

``python -m a2cm_phys.export RUN --out DIR`` writes one ONNX model per actor and
``policy.json`` (:mod:`.spec`); :class:`Team` plays them, :class:`Actor` one of them::

    from a2cm_phys import make_env
    from a2cm_phys.deploy import Team, pretrained_dir

    team = Team.load(pretrained_dir("grid_collision"))
    env = make_env(team.scenario["name"])
    obs, _ = env.reset(seed=0)
    while env.agents:
        obs, rewards, terminated, truncated, infos = env.step(team.act(obs))

Importing this package imports neither torch nor gymnasium nor the simulators.
"""

from __future__ import annotations

from .pretrained import pretrained_dir, pretrained_names
from .runtime import Actor, Team, clip_to_box, clip_to_disc
from .spec import FORMAT, POLICY_FILE, DeployError, read_policy

__all__ = [
    "FORMAT",
    "POLICY_FILE",
    "Actor",
    "DeployError",
    "Team",
    "clip_to_box",
    "clip_to_disc",
    "load_team",
    "pretrained_dir",
    "pretrained_names",
    "read_policy",
]

ONNX_PREFIX, PRETRAINED_PREFIX = "onnx:", "pretrained:"
"""How a command names an exported team: ``onnx:DIR`` or ``pretrained:NAME``."""


def load_team(spec: str) -> Team | None:
    """The team ``spec`` names, ``onnx:DIR`` (an exported folder) or ``pretrained:NAME``
    (:func:`pretrained_dir`); ``None`` if ``spec`` has neither prefix. A
    :class:`DeployError` if the folder is not an exported team or the name is unknown."""
    if spec.startswith(ONNX_PREFIX):
        return Team.load(spec.removeprefix(ONNX_PREFIX))
    if spec.startswith(PRETRAINED_PREFIX):
        return Team.load(pretrained_dir(spec.removeprefix(PRETRAINED_PREFIX)))
    return None
