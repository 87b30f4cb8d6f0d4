"""The pretrained teams that come with the package (``a2cm_phys/pretrained/NAME/``): exported
teams trained by the package's own commands, as ``a2cm_phys/pretrained/README.md`` says."""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

from .spec import POLICY_FILE, DeployError


def pretrained_root() -> Path:
    """The folder of the pretrained teams inside the installed package."""
    return Path(str(files("a2cm_phys").joinpath("pretrained")))


def pretrained_names() -> list[str]:
    """The names of the pretrained teams, sorted (e.g. ``grid_collision``, ``phys_cont``)."""
    root = pretrained_root()
    if not root.is_dir():
        return []
    return sorted(p.name for p in root.iterdir() if (p / POLICY_FILE).is_file())


def pretrained_dir(name: str) -> Path:
    """The folder of the pretrained team ``name`` (load it with ``Team.load``); a
    :class:`DeployError` naming the available ones if there is none of that name."""
    names = pretrained_names()
    if name not in names:
        available = ", ".join(names) if names else "none (the package was installed without them)"
        raise DeployError(f"no pretrained team {name!r} (available: {available})")
    return pretrained_root() / name
