"""The command line: every subcommand of the measurement contract exists and has a --help."""

import argparse
import subprocess
import sys
from pathlib import Path

import pytest

from optrack.cli import build_parser, main

CONTRACT = [
    ["sim"],
    ["detect"],
    ["eval"],
    ["calibrate", "intrinsics"],
    ["calibrate", "stereo"],
    ["calibrate", "network"],
    ["calibrate", "refine"],
    ["bench"],
    ["run"],
    ["gui"],
    ["sensors"],
    ["record"],
    ["cloud"],
    ["node", "detect"],
    ["node", "track"],
]


def subcommands(parser: argparse.ArgumentParser, prefix=()):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                path = (*prefix, name)
                yield path, sub
                yield from subcommands(sub, path)


def test_every_command_of_the_measurement_contract_exists():
    declared = {path for path, _ in subcommands(build_parser())}
    for command in CONTRACT:
        assert tuple(command) in declared


@pytest.mark.parametrize("command", [list(p) for p, _ in subcommands(build_parser())], ids=" ".join)
def test_every_subcommand_has_help(command, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main([*command, "--help"])
    assert exit_info.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: optrack " + " ".join(command))


def test_console_script_is_installed_and_answers():
    optrack = Path(sys.executable).parent / "optrack"
    result = subprocess.run([str(optrack), "--version"], capture_output=True, text=True, check=True)
    assert result.stdout.startswith("optrack ")


def test_no_command_prints_usage_and_fails(capsys):
    assert main([]) == 2
    assert "usage: optrack" in capsys.readouterr().err


def test_the_parser_loads_no_heavy_library():
    """`optrack --help` stays fast: declaring every command imports none of the heavy
    libraries (each package's cli.py imports them only when its command runs)."""
    heavy = ("open3d", "scipy", "zenoh", "PySide6", "gtsam", "numba", "sklearn")
    code = (
        "import sys, optrack.cli as c; c.build_parser(); "
        f"print(','.join(m for m in {heavy!r} if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "", f"building the parser imported {out.stdout.strip()}"
