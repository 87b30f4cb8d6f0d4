"""``--set KEY=VALUE`` takes one pair per flag in every command (issue 31): the next word
is never swallowed, repeated flags add up, and the old several-pairs form is refused with
a message that shows the repeated form."""

from __future__ import annotations

import argparse
import importlib

import pytest

from a2cm_phys.commands import COMMANDS
from a2cm_phys.commands.options import Parser, UsageError, add_scenario_options


def parser() -> Parser:
    """A parser with ``--scenario``/``--set``/``--preset`` and one optional positional."""
    p = Parser(prog="test")
    p.add_argument("run", nargs="?")
    add_scenario_options(p)
    return p


def test_set_leaves_the_next_word_to_the_positional() -> None:
    args = parser().parse_args(["--set", "evader=flee", "logs/run"])
    assert args.set == ["evader=flee"]
    assert args.run == "logs/run"


def test_repeated_set_flags_add_up_in_order() -> None:
    args = parser().parse_args(["--set", "size=4", "--set=train.lr=0.1", "--set", "size=3"])
    assert args.set == ["size=4", "train.lr=0.1", "size=3"]


@pytest.mark.parametrize(
    "argv",
    [
        ["--set", "size=4", "pursuers=2"],
        ["--set", "size=4", "pursuers=2", "logs/run"],
        ["logs/run", "--set", "train.lr=0.1", "train.updates=5"],
    ],
)
def test_several_pairs_after_one_flag_are_refused_with_the_repeated_form(argv: list[str]) -> None:
    with pytest.raises(UsageError) as err:
        parser().parse_args(argv)
    first, second = argv[argv.index("--set") + 1 : argv.index("--set") + 3]
    assert f"--set {first} --set {second}" in str(err.value)


def test_a_positional_that_is_no_assignment_is_not_mistaken_for_one() -> None:
    args = parser().parse_args(["--set", "size=4", "run=folder/x"[4:]])
    assert args.run == "folder/x"


@pytest.mark.parametrize("command", COMMANDS)
def test_every_command_takes_one_pair_per_flag(command: str) -> None:
    """Each command that has ``--set`` appends one pair per flag."""
    p = importlib.import_module(f"a2cm_phys.commands.{command}").build_parser()
    flags = {a.dest: a for a in p._actions}
    if "set" not in flags:
        pytest.skip(f"{command} has no --set")
    assert flags["set"].nargs is None
    assert isinstance(flags["set"], argparse._AppendAction)
