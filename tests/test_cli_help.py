"""Every command's ``--help`` (issue 31): every option has help that says its default (or
is a flag, required, or a repeatable option that is empty by default), and ``--help``
imports nothing heavy (torch, matplotlib, ray), so that it answers at once."""

from __future__ import annotations

import argparse
import importlib
import subprocess
import sys

import pytest

from a2cm_phys.commands import COMMANDS

FLAGS = (argparse._StoreTrueAction, argparse._StoreConstAction, argparse._CountAction)
HEAVY = ("torch", "matplotlib", "ray")
"""Packages ``--help`` must not import (each takes from a fraction of a second to seconds)."""


def _options(command: str) -> tuple[argparse.ArgumentParser, list[argparse.Action]]:
    parser = importlib.import_module(f"a2cm_phys.commands.{command}").build_parser()
    actions = [a for a in parser._actions if not isinstance(a, argparse._HelpAction)]
    return parser, [a for a in actions if a.option_strings]


def _says_default(parser: argparse.ArgumentParser, action: argparse.Action) -> bool:
    """Whether the option's help, as ``--help`` prints it, mentions its default."""
    return "default" in parser._get_formatter()._expand_help(action)


@pytest.mark.parametrize("command", COMMANDS)
def test_every_option_has_help_with_its_default(command):
    parser, actions = _options(command)
    assert actions, command
    no_help = [a.option_strings[0] for a in actions if not (a.help or "").strip()]
    assert not no_help, f"{command}: options without help: {no_help}"
    exempt = [
        a
        for a in actions
        if isinstance(a, FLAGS)
        or a.required
        or (isinstance(a, argparse._AppendAction) and a.default == [])
    ]
    silent = [
        a.option_strings[0] for a in actions if a not in exempt and not _says_default(parser, a)
    ]
    assert not silent, f"{command}: options whose help says no default: {silent}"
    assert "default" in parser.format_help()


def _imported(command: str) -> set[str]:
    """The top-level packages ``python -m a2cm_phys.<command> --help`` imports."""
    done = subprocess.run(
        [sys.executable, "-X", "importtime", "-m", f"a2cm_phys.{command}", "--help"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert "usage:" in done.stdout
    names = set()
    for line in done.stderr.splitlines():
        if line.startswith("import time:") and line.count("|") == 2:
            names.add(line.rsplit("|", 1)[1].strip().split(".")[0])
    return names


@pytest.mark.parametrize("command", COMMANDS)
def test_help_imports_nothing_heavy(command):
    imported = _imported(command)
    assert "a2cm_phys" in imported  # the parse is right
    heavy = sorted(set(HEAVY) & imported)
    assert not heavy, f"python -m a2cm_phys.{command} --help imports {heavy}"
