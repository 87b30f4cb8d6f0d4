"""What every ``python -m a2cm_phys.<command>`` shares: option spellings, checks, errors.

- :class:`Parser`: an ``argparse`` parser whose mistakes raise :class:`UsageError` instead
  of printing the usage and exiting, so that every command reports them the same way.
- :func:`run_cli`: runs a command's body and turns a user's mistake (:class:`UsageError`,
  :class:`~a2cm_phys.config.ConfigError`, an unreadable or unwritable path) into one line
  ``error: …`` on stderr and exit status 2, Ctrl-C into 130, without a traceback.
- :func:`add_scenario_options` / :func:`scenario_from_args` / :func:`train_from_args`: the
  one definition of ``--scenario``, ``--set KEY=VALUE`` (``train.KEY`` sets a training
  option) and ``--preset NAME``; explicit options win over ``--set``, which wins over the
  preset.
- argparse ``type=`` checks (:func:`int_range`, :func:`positive_float`, :data:`SEED`) and
  path checks (:func:`writable_dir`, :func:`output_file`) that run before anything is written.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NoReturn

from ..base.errors import UserError
from ..base.exitcodes import EXIT_INTERRUPTED, EXIT_NO_SPACE, EXIT_USAGE, OUT_OF_SPACE
from ..config import Scenario, Train, load_scenario, load_train, parse_assignments
from ..config import preset as preset_values
from ..training.rundir import is_run_file

MAX_SEED = 2**64 - 1
"""Largest seed: seeds feed 64-bit generators."""


class UsageError(UserError):
    """A command was given something it cannot use; the message names the option or file."""


ASSIGNMENT = re.compile(r"^[A-Za-z_][\w.]*=")
"""What a ``--set`` item looks like: ``KEY=VALUE`` (a dotted key)."""


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Help that ends each option with its default, where it has one worth showing (not
    ``None``, a flag's ``False`` or an empty list: their help says what happens)."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        default = action.default
        shown = not (
            default is None
            or default is False
            or default == []
            or default == argparse.SUPPRESS
            or isinstance(action, argparse._HelpAction)
        )
        if shown and "%(default)" not in text and "default" not in text:
            text += " (default: %(default)s)"
        return text


class Parser(argparse.ArgumentParser):
    """An ``ArgumentParser`` that raises :class:`UsageError` rather than exiting, shows
    each option's default in ``--help``, and takes one ``KEY=VALUE`` per ``--set``."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, **kwargs)

    def parse_known_args(self, args: Sequence[str] | None = None, namespace: Any = None) -> Any:
        """argparse's, after refusing ``--set A=1 B=2`` (the old several-pairs form)."""
        argv = list(sys.argv[1:] if args is None else args)
        for i, word in enumerate(argv[:-2]):
            if word == "--set" and ASSIGNMENT.match(argv[i + 2]):
                raise UsageError(
                    f"--set takes one KEY=VALUE per flag: write --set {argv[i + 1]}"
                    f" --set {argv[i + 2]} (repeat --set for each pair)"
                )
        return super().parse_known_args(argv, namespace)

    def error(self, message: str) -> NoReturn:
        """Called by argparse on a bad command line."""
        raise UsageError(message)


def run_cli(body: Callable[[Sequence[str]], int], argv: Sequence[str] | None = None) -> int:
    """Run ``body(argv)`` (default ``sys.argv[1:]``) and return its exit status; a user error
    prints ``error: …`` (one line) and gives :data:`EXIT_USAGE`, Ctrl-C gives
    :data:`EXIT_INTERRUPTED`, running out of memory is one line too, a closed stdout
    (``| head``) ends quietly."""
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        return body(argv)
    except UserError as err:
        return fail(str(err))
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except MemoryError as err:  # values within the limits can still be too much for a machine
        return fail(f"out of memory ({err or 'MemoryError'}): ask for less (games, batch, arena)")
    except BrokenPipeError:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except OSError as err:  # an unreadable input or an unwritable output
        where = f"{err.filename}: " if err.filename else ""
        if err.errno in OUT_OF_SPACE:  # the machine's fault, not the user's
            print(f"error: {where}{err.strerror or err} (free some space)", file=sys.stderr)
            return EXIT_NO_SPACE
        return fail(f"{where}{err.strerror or err}")


def fail(message: str) -> int:
    """Print ``error: message`` as one line on stderr; return :data:`EXIT_USAGE`."""
    print(f"error: {' '.join(message.split())}", file=sys.stderr)
    return EXIT_USAGE


# --------------------------------------------------------------------------- value checks


def int_range(lo: int, hi: int | None = None, why: str = "") -> Callable[[str], int]:
    """An argparse type: an integer in ``[lo, hi]`` (``why`` explains the upper bound)."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
        if value < lo or (hi is not None and value > hi):
            bound = f"between {lo} and {hi}" if hi is not None else f">= {lo}"
            raise argparse.ArgumentTypeError(f"must be {bound}{why}, got {value}")
        return value

    parse.__name__ = "integer"
    return parse


SEED = int_range(0, MAX_SEED, " (a 64-bit seed)")
"""An argparse type for seeds."""


def positive_float(text: str) -> float:
    """An argparse type: a finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not 0 < value < float("inf"):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text}")
    return value


def check_device(device: str, option: str = "--device") -> None:
    """A :class:`UsageError` unless torch can use ``device`` on this machine."""
    import torch

    try:
        dev = torch.device(device)
    except (RuntimeError, ValueError):
        raise UsageError(f"{option}: unknown device {device!r} (e.g. cpu, cuda, cuda:1)") from None
    if dev.type == "cpu":
        return
    if dev.type == "cuda":
        if not torch.cuda.is_available():
            raise UsageError(f"{option}: {device!r}, but CUDA is not available on this machine")
        if dev.index is not None and dev.index >= torch.cuda.device_count():
            raise UsageError(
                f"{option}: {device!r}, but this machine has {torch.cuda.device_count()} CUDA"
                " device(s)"
            )
        return
    if dev.type == "mps" and torch.backends.mps.is_available():
        return
    raise UsageError(f"{option}: device {device!r} is not available on this machine")


def writable_dir(path: str | Path, option: str) -> Path:
    """``path`` as a folder that exists or can be created and written, created by nobody
    yet: a :class:`UsageError` naming ``option`` if it is empty, a file, a link to nothing,
    or cannot be written."""
    if str(path).strip() == "":
        raise UsageError(f"{option}: an empty folder name (give a folder, e.g. {option} .)")
    path = Path(path)
    probe = path
    while not probe.exists():
        if probe.is_symlink():
            raise UsageError(
                f"{option} {path}: {probe} is a link to {os.readlink(probe)}, which does not exist"
            )
        if probe.parent == probe:
            break
        probe = probe.parent
    if probe.exists() and not probe.is_dir():
        what = "is a file" if probe == path else f"cannot be created ({probe} is a file)"
        raise UsageError(f"{option} {path}: {what}")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise UsageError(f"{option} {path}: cannot write in {probe} (permission denied)")
    return path


def output_file(path: str | Path, option: str, suffixes: Sequence[str] = ()) -> Path:
    """A file to write: a :class:`UsageError`, before anything is opened, if its extension
    is not one of ``suffixes`` (when given), if it is one of a run's own files (its log,
    checkpoint, config or summary: an output never replaces them), if it is a folder or if
    its folder can't be made."""
    path = Path(path)
    if suffixes and path.suffix.lower() not in suffixes:
        raise UsageError(f"{option} {path}: expected a {' or '.join(suffixes)} file")
    if is_run_file(path):
        raise UsageError(
            f"{option} {path}: is one of the run's own files; write the output elsewhere"
        )
    if path.is_dir():
        raise UsageError(f"{option} {path}: is a folder, expected a file name")
    writable_dir(path.parent, option)
    return path


# --------------------------------------------------------------------------- scenario options


def add_scenario_options(
    parser: argparse.ArgumentParser,
    *,
    default: str | None = None,
    train: bool = True,
    scenario: bool = True,
    scenario_help: str = "scenario name (see a2cm_phys/scenarios/) or path to a TOML file",
) -> None:
    """Add ``--scenario`` (unless not ``scenario``), ``--set KEY=VALUE`` and (with
    ``train``) ``--preset NAME``."""
    if scenario:
        parser.add_argument("--scenario", default=default, help=scenario_help)
    what = "scenario key, or train.KEY for a training option" if train else "scenario key"
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help=f"override a {what}; one pair per flag, repeat the flag for more"
        " (values are TOML: -2, flee, true)",
    )
    if train:
        from ..config import PRESETS

        parser.add_argument(
            "--preset",
            metavar="NAME",
            help=f"a named set of training options ({', '.join(PRESETS)}); explicit options win"
            " (default: none, this project's own defaults)",
        )


def split_assignments(items: Sequence[str]) -> tuple[dict[str, Any], dict[str, Any]]:
    """``--set`` items as (scenario overrides, training overrides without ``train.``)."""
    assignments = parse_assignments(items)
    train = {k.removeprefix("train."): v for k, v in assignments.items() if k.startswith("train.")}
    scenario = {k: v for k, v in assignments.items() if not k.startswith("train.")}
    return scenario, train


def scenario_from_args(args: argparse.Namespace, *, train: bool = True) -> Scenario:
    """The scenario of ``--scenario`` with its ``--set`` overrides (a train.KEY is an error
    unless the command trains)."""
    if not args.scenario:
        raise UsageError("--scenario is required")
    overrides, train_set = split_assignments(args.set)
    if train_set and not train:
        raise UsageError(f"--set train.{next(iter(train_set))}: this command does not train")
    return load_scenario(args.scenario, overrides)


def train_values(args: argparse.Namespace, flags: dict[str, Any] | None = None) -> dict[str, Any]:
    """The training options given: the ``--preset``, then ``--set train.KEY=…``, then
    ``flags`` (the command's explicit options, ``None`` meaning not given)."""
    preset = getattr(args, "preset", None)
    values = preset_values(preset) if preset is not None else {}
    values.update(split_assignments(args.set)[1])
    values.update({k: v for k, v in (flags or {}).items() if v is not None})
    return values


def train_from_args(args: argparse.Namespace, flags: dict[str, Any] | None = None) -> Train:
    """The validated :class:`Train` of :func:`train_values`, its device checked."""
    cfg = load_train(train_values(args, flags))
    check_device(cfg.device, "--device")
    return cfg


def add_logdir(parser: argparse.ArgumentParser, default: str, help: str) -> None:
    """``--logdir DIR`` (and the deprecated spelling ``--sweep-dir``)."""
    parser.add_argument("--logdir", "--sweep-dir", dest="logdir", default=default, help=help)
