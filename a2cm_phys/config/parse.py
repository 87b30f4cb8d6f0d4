"""Building config dataclasses from plain data: keys, types and values checked, and every
error a :class:`ConfigError` naming its source (a file, ``--set``, overrides) and the
dotted key at fault. Whether the data came from a TOML file, ``make_env`` keyword overrides
or ``--set key=value``, it passes through :func:`build`, so the same checks and messages
apply everywhere."""

from __future__ import annotations

import copy
import dataclasses
import math
import types
import typing
from collections.abc import Iterable, Mapping
from typing import Any, Literal

import numpy as np
import tomllib

from ..base.errors import UserError


class ConfigError(UserError, ValueError):
    """A scenario or training setting is wrong; the message names the source and the key."""


def check_limits(obj: Any, limits: Mapping[str, tuple[int, str]]) -> None:
    """Raise ``ValueError`` naming the key of the first value above its limit, or (for a
    scenario) a ``name`` that is not a plain file name (run directories are named after it)."""
    for key, (limit, why) in limits.items():
        value = obj
        for part in key.split("."):
            value = getattr(value, part)
        if value is not None and value > limit:
            raise InvalidKey(key, f"must be at most {limit:,} ({why}), got {value:,}")
    name = getattr(obj, "name", None)
    if name is not None and (not name or name[0] == "." or set(name) & set("/\\\0")):
        raise InvalidKey("name", f"must be a file name (no /, \\, no leading '.'), got {name!r}")


class InvalidKey(ValueError):
    """A value found wrong while building, with the dotted key it concerns: :func:`build`
    turns it into a :class:`ConfigError` naming the source and the key."""

    def __init__(self, key: str, message: str) -> None:
        super().__init__(message)
        self.key = key


# --------------------------------------------------------------------------- building


def build(cls: type, data: Mapping[str, Any], source: str, prefix: str = "") -> Any:
    """Build dataclass ``cls`` from nested ``data``, checking keys, types and values.

    ``source`` names where the data came from (a file path, ``"overrides"``), and is put
    in front of every error message together with the dotted key at fault.
    """
    try:
        obj = _build(cls, data, prefix)
        if hasattr(obj, "validate"):
            obj.validate()
        return obj
    except InvalidKey as err:
        key = f"{prefix}{err.key}" if prefix and not err.key.startswith(prefix) else err.key
        raise ConfigError(f"{source}: key '{key}': {err}") from None


def _build(cls: type, data: Mapping[str, Any], prefix: str) -> Any:
    if not isinstance(data, Mapping):
        raise InvalidKey(prefix.rstrip(".") or "<root>", f"expected a table, got {data!r}")
    data = expand_shorthands(cls, data)
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        known = ", ".join(fields)
        raise InvalidKey(f"{prefix}{unknown[0]}", f"unknown key (known keys: {known})")
    kwargs = {}
    for name, value in data.items():
        key, hint = f"{prefix}{name}", hints[name]
        if dataclasses.is_dataclass(hint):
            kwargs[name] = _build(hint, value, f"{key}.")
        elif _table_list(hint):
            kwargs[name] = _build_list(typing.get_args(hint)[0], value, key)
        else:
            kwargs[name] = _coerce(value, hint, key)
    missing = [
        f.name
        for f in fields.values()
        if f.name not in kwargs
        and f.default is dataclasses.MISSING
        and f.default_factory is dataclasses.MISSING
    ]
    if missing:
        raise InvalidKey(f"{prefix}{missing[0]}", "missing (this key has no default)")
    obj = cls(**kwargs)
    if prefix and hasattr(obj, "validate") and _table_list_item(prefix):
        try:  # an item of a list of tables checks itself; its errors name the item
            obj.validate()
        except InvalidKey as err:
            raise InvalidKey(f"{prefix}{err.key}", str(err)) from None
    return obj


def _table_list(hint: Any) -> bool:
    """Whether ``hint`` is ``tuple[SomeDataclass, ...]`` (a TOML array of tables)."""
    args = typing.get_args(hint)
    return (
        typing.get_origin(hint) is tuple
        and len(args) == 2
        and args[1] is Ellipsis
        and dataclasses.is_dataclass(args[0])
    )


def _table_list_item(prefix: str) -> bool:
    return prefix.endswith("].")


def _build_list(cls: type, value: Any, key: str) -> tuple[Any, ...]:
    """A tuple of ``cls`` from a list of tables (``[[key]]`` in TOML), each item's errors
    naming ``key[i].field``."""
    if not isinstance(value, (list, tuple)):
        raise InvalidKey(key, f"expected a list of tables ([[{key}]]), got {value!r}")
    return tuple(_build(cls, item, f"{key}[{i}].") for i, item in enumerate(value))


def expand_shorthands(cls: type, data: Mapping[str, Any]) -> dict[str, Any]:
    """``data`` with every bare-string value of a table that has a shorthand written out as
    that table (``start = "random"`` → ``start = {kind = "random"}``), defaults left unset,
    so that a dotted override (``start.min_evader_distance``) has a table to reach."""
    hints = typing.get_type_hints(cls)
    out = dict(data)
    for name, value in data.items():
        hint = hints.get(name)
        if dataclasses.is_dataclass(hint) and isinstance(value, str) and hasattr(hint, "shorthand"):
            out[name] = {hint.shorthand: value}
    return out


_INTEGERS = (int, np.integer)
_REALS = (int, float, np.integer, np.floating)


def _coerce(value: Any, hint: Any, key: str) -> Any:
    origin = typing.get_origin(hint)
    if origin is Literal:
        choices = typing.get_args(hint)
        if value not in choices:
            raise InvalidKey(key, f"must be one of {', '.join(map(repr, choices))}, got {value!r}")
        return value
    if origin in (typing.Union, types.UnionType):
        args = [arg for arg in typing.get_args(hint) if arg is not type(None)]
        if len(args) != 1 or len(typing.get_args(hint)) != 2:
            raise TypeError(f"unsupported annotation for {key}: {hint}")
        return None if value is None else _coerce(value, args[0], key)  # X | None
    # numpy scalars (np.int64, np.float32, np.bool_) are taken as the Python values they
    # hold, so that values computed with numpy pass where the same Python numbers do.
    if hint is float:
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, _REALS):
            raise InvalidKey(key, f"must be a number, got {value!r}")
        if not math.isfinite(value):
            raise InvalidKey(key, f"must be a finite number, got {value!r}")
        return float(value)
    if hint is int:
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, _INTEGERS):
            raise InvalidKey(key, f"must be an integer, got {value!r}")
        return int(value)
    if hint is bool:
        if not isinstance(value, (bool, np.bool_)):
            raise InvalidKey(key, f"must be true or false, got {value!r}")
        return bool(value)
    if hint is str and not isinstance(value, str):
        raise InvalidKey(key, f"must be a string, got {value!r}")
    return value


def to_dict(obj: Any) -> dict[str, Any]:
    """A plain nested dict of a config dataclass (for JSON, MCAP metadata, TOML). A field
    whose metadata has ``omit_default`` is left out while it holds its default, so that
    configs that do not use a key added later are written exactly as before it existed;
    building from the dict restores the default."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if f.metadata.get("omit_default") and value == f.default:
            continue
        if dataclasses.is_dataclass(value):
            value = to_dict(value)
        elif isinstance(value, tuple) and value and dataclasses.is_dataclass(value[0]):
            value = [to_dict(item) for item in value]
        else:
            value = copy.deepcopy(value)
        out[f.name] = value
    return out


# --------------------------------------------------------------------------- overrides


def parse_assignments(items: Iterable[str], source: str = "--set") -> dict[str, Any]:
    """Parse ``key=value`` strings; values are read as TOML (``-1``, ``"flee"``, ``true``).

    A bare word that is not valid TOML is taken as a string, so ``evader=flee`` works.
    """
    out: dict[str, Any] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ConfigError(f"{source}: '{item}' is not of the form key=value")
        try:
            out[key] = tomllib.loads(f"v = {raw.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            out[key] = raw.strip()
    return out


def merge_overrides(data: Mapping[str, Any], overrides: Mapping[str, Any]) -> dict[str, Any]:
    """Return ``data`` updated with ``overrides``; dotted keys and nested dicts both work."""
    merged: dict[str, Any] = {
        k: (dict(v) if isinstance(v, Mapping) else v) for k, v in data.items()
    }
    for dotted, value in overrides.items():
        *parents, leaf = dotted.split(".")
        table = merged
        for part in parents:
            table = table.setdefault(part, {})
            if not isinstance(table, dict):
                raise ConfigError(f"overrides: key '{dotted}': '{part}' is not a table")
        if isinstance(value, Mapping) and isinstance(table.get(leaf), Mapping):
            table[leaf] = merge_overrides(table[leaf], value)
        else:
            table[leaf] = value
    return merged
