"""Loading configs: named or file scenarios (TOML) with overrides, training options, and a
stored run's training config completed for keys added after it was written."""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import tomllib

from .parse import ConfigError, build, expand_shorthands, merge_overrides, to_dict
from .resolve import CONTROL_DEFAULTS
from .scenario import Scenario
from .train import Train

SCENARIO_DIR = Path(__file__).resolve().parents[1] / "scenarios"
"""Folder of the named scenarios, package data of ``a2cm_phys`` (so a wheel has them too);
the checkout's top-level ``scenarios/`` is a symbolic link to it."""


def scenario_names() -> list[str]:
    """Names of the scenarios shipped in ``scenarios/``."""
    return sorted(p.stem for p in SCENARIO_DIR.glob("*.toml"))


def resolve_scenario_path(scenario: str | Path) -> Path:
    """A scenario name (``grid``) or a path to a TOML file, as an existing path."""
    path = Path(scenario)
    if path.suffix == ".toml" or path.exists():
        if not path.is_file():
            raise ConfigError(f"{path}: no such scenario file")
        return path
    named = SCENARIO_DIR / f"{scenario}.toml"
    if not named.is_file():
        raise ConfigError(
            f"unknown scenario '{scenario}' (named scenarios: {', '.join(scenario_names())};"
            " or give a path to a .toml file)"
        )
    return named


def read_toml(path: Path) -> dict[str, Any]:
    """Read a TOML file, turning syntax errors, text that is not UTF-8 and unreadable files
    into a :class:`ConfigError` naming the file."""
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{path}: invalid TOML: {err}") from None
    except UnicodeDecodeError as err:  # tomllib decodes the whole file before parsing
        raise ConfigError(
            f"{path}: not UTF-8 text (TOML files must be UTF-8; byte 0x{err.object[err.start]:02x}"
            f" at offset {err.start} is not)"
        ) from None
    except OSError as err:
        raise ConfigError(f"{path}: cannot read: {err.strerror}") from None


def load_scenario(
    scenario: str | Path | Scenario, overrides: Mapping[str, Any] | None = None
) -> Scenario:
    """Load a named or file scenario (or take a :class:`Scenario`), apply overrides, validate.

    Overrides are checked exactly like the file: ``load_scenario("grid", {"size": 1})``
    fails with a message naming ``overrides`` and the key ``size``. A ``scenario`` of any
    other type (``load_scenario(123)``) is a ``TypeError`` naming the argument.
    """
    if isinstance(scenario, Scenario):
        data, source = to_dict(scenario), f"scenario '{scenario.name}'"
    elif not isinstance(scenario, (str, os.PathLike)):
        raise TypeError(
            "scenario: expected a scenario name (e.g. 'grid'; see scenario_names()), a path"
            f" to a TOML file or a Scenario, got {type(scenario).__name__} {scenario!r}"
        )
    else:
        path = resolve_scenario_path(scenario)
        data, source = read_toml(path), str(path)
        data.setdefault("name", path.stem)
    if overrides:
        build(Scenario, data, source)  # the file alone must be valid, and be blamed if not
        data = expand_shorthands(Scenario, data)  # not to_dict: defaults are resolved later
        overrides = expand_shorthands(Scenario, overrides)  # start = "random" keeps the rest
        data, source = merge_overrides(data, overrides), f"{source} (with overrides)"
    return build(Scenario, data, source)


def load_train(
    overrides: Mapping[str, Any] | None = None, source: str = "training options"
) -> Train:
    """A validated :class:`Train` from the defaults and ``overrides``."""
    return build(Train, dict(overrides or {}), source)


STORED_BEFORE: dict[str, Any] = {"entropy_schedule": "constant"}
"""What runs stored before a key existed trained with (every run before the entropy
schedule had a constant coefficient)."""


def stored_train(values: Mapping[str, Any]) -> dict[str, Any]:
    """A stored run's training config completed for keys added after it was written:
    the discrete values of :data:`CONTROL_DEFAULTS` (such runs had none of these pieces),
    :data:`STORED_BEFORE`, then today's defaults."""
    added = {f.name: f.default for f in dataclasses.fields(Train)}
    return {**added, **CONTROL_DEFAULTS["discrete"], **STORED_BEFORE, **values}
