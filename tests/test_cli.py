"""The command line: every subcommand of the measurement contract has a --help, and
commands whose part is not built yet say so in one line instead of faking output."""

import argparse
import subprocess
import sys
from pathlib import Path

import pytest

from optrack.cli import EXIT_UNAVAILABLE, NotAvailable, build_parser, main

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


def unavailable_invocations():
    minimal = {
        "sim": ["mixed", "--out", "x"],
        "detect": ["x.pcd"],
        "eval": ["rec"],
        "intrinsics": ["a.png", "--board", "9x6", "--square", "0.025"],
        "stereo": ["--board", "9x6", "--square", "0.025", "--left", "l.png", "--right", "r.png"],
        "network": ["rec", "--out", "c.yaml"],
        "refine": ["rec", "--calibration", "c.yaml", "--out", "d.yaml"],
        "run": ["--headless"],
        "sensors": [],
        "record": ["--sensor", "openni://Dummy", "--seconds", "1", "--out", "x"],
        "track": ["--site", "s"],
    }
    for path, sub in subcommands(build_parser()):
        handler = sub.get_default("handler")
        if isinstance(handler, NotAvailable):
            extra = (
                ["--sensor", "openni://Dummy", "--site", "s"]
                if path == ("node", "detect")
                else minimal.get(path[-1], [])
            )
            yield [*path, *extra]


def test_commands_not_built_yet_say_so_in_one_line(capsys):
    invocations = list(unavailable_invocations())
    if not invocations:
        pytest.skip("every command is built: nothing is unavailable any more")
    for argv in invocations:
        assert main(argv) == EXIT_UNAVAILABLE, argv
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "not available yet" in err, argv


def test_no_command_prints_usage_and_fails(capsys):
    assert main([]) == 2
    assert "usage: optrack" in capsys.readouterr().err
