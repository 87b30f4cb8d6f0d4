"""a2cm_phys: cooperative multi-agent pursuit–evasion on a grid and in pymunk physics,
with the A2C and A2CM trainers of Paczolay & Harmati (2021).

The data path: ``config`` (scenario) → ``envs`` (game cores and APIs) → ``algos`` (models,
returns, learner) → ``record`` (MCAP logs) → ``training`` → ``analysis`` → ``commands``
(``docs/design.md``).

Importing the package is light: its names (:func:`make_env`, :class:`Scenario`, …) load
on first use, so that :mod:`a2cm_phys.deploy` runs a trained team without torch,
gymnasium or the simulators. The Gymnasium id :data:`GYM_ID` is registered as soon as
both this package and gymnasium are imported, in either order.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import sys
from types import ModuleType
from typing import Any

from .base.versions import __version__

GYM_ID = "a2cm_phys/Pursuit-v0"
"""Gymnasium id of the joint view (kwarg ``scenario``)."""

_LAZY = {
    "ConfigError": "a2cm_phys.config",
    "Scenario": "a2cm_phys.config",
    "load_scenario": "a2cm_phys.config",
    "PursuitParallelEnv": "a2cm_phys.envs.parallel",
    "make_env": "a2cm_phys.envs.parallel",
}
"""The package's names and the modules that define them, imported on first use."""

__all__ = ["GYM_ID", "ConfigError", "PursuitParallelEnv", "Scenario", "__version__"]
__all__ += ["load_scenario", "make_env"]


def __getattr__(name: str) -> Any:
    """Load one of the package's names from its module on first use."""
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'a2cm_phys' has no attribute {name!r}")


def _register(gymnasium: ModuleType) -> None:
    if GYM_ID not in gymnasium.registry:
        gymnasium.register(id=GYM_ID, entry_point="a2cm_phys.envs.gym:PursuitEnv")


class _RegisterWithGymnasium(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Registers :data:`GYM_ID` right after gymnasium is imported (Python has no
    post-import hook of its own): it finds gymnasium's spec as usual, then runs
    gymnasium's loader and registers once the module is whole."""

    def __init__(self) -> None:
        self.loader: importlib.abc.Loader | None = None

    def find_spec(self, name: str, path: Any = None, target: Any = None) -> Any:
        """gymnasium's own spec, with this object as its loader."""
        if name != "gymnasium":
            return None
        sys.meta_path.remove(self)
        spec = importlib.util.find_spec(name)  # every other finder, as Python would ask
        if spec is None or spec.loader is None:
            return spec
        self.loader, spec.loader = spec.loader, self
        return spec

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType | None:
        """gymnasium's loader's module."""
        return self.loader.create_module(spec)  # type: ignore[union-attr]

    def __getattr__(self, name: str) -> Any:  # resources, code, … as gymnasium's loader
        return getattr(self.loader, name)

    def exec_module(self, module: ModuleType) -> None:
        """Run gymnasium, then register the id."""
        self.loader.exec_module(module)  # type: ignore[union-attr]
        _register(module)


if "gymnasium" in sys.modules:
    _register(sys.modules["gymnasium"])
else:
    sys.meta_path.insert(0, _RegisterWithGymnasium())
