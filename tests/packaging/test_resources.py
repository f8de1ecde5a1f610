"""The package's resources: inside optrack/resources, read through importlib.resources."""

from __future__ import annotations

import ast
import fnmatch
import importlib.metadata
import tomllib
from pathlib import Path

import optrack
from optrack.resources import resource_path, scenario_dir
from optrack.sim.scenario import builtin_scenarios, load_scenario

REPO = Path(__file__).resolve().parents[2]
PYPROJECT = tomllib.loads((REPO / "pyproject.toml").read_text())


def test_scenarios_come_from_the_package() -> None:
    names = builtin_scenarios()
    assert {"mixed", "crowd", "calibration"} <= set(names)
    assert scenario_dir() == Path(optrack.__file__).parent / "resources" / "scenarios"
    assert load_scenario("mixed").name


def test_desktop_entry_icon_and_default_configs_are_resources() -> None:
    entry = resource_path("optrack.desktop").read_text()
    assert "Exec=optrack gui" in entry and "Icon=optrack" in entry
    assert resource_path("icons", "optrack.svg").read_text().lstrip().startswith("<")
    for name in ("site.yaml", "site.env", "sensor.env"):
        assert resource_path("config", name).is_file()


def test_every_resource_file_is_declared_package_data() -> None:
    patterns = PYPROJECT["tool"]["setuptools"]["package-data"]["optrack.resources"]
    root = resource_path()
    files = [
        p.relative_to(root).as_posix()
        for p in root.rglob("*")
        if p.is_file() and "__pycache__" not in p.parts and p.suffix != ".py"
    ]
    assert files
    missing = [f for f in files if not any(fnmatch.fnmatch(f, pat) for pat in patterns)]
    assert missing == [], f"resources not in the wheel's package-data: {missing}"


def test_no_module_reads_a_path_relative_to_the_checkout() -> None:
    offenders = []
    for path in [*(REPO / "optrack").rglob("*.py"), *(REPO / "app").rglob("*.py")]:
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Constant) and node.value == "resources":
                offenders.append(f"{path.relative_to(REPO)}:{node.lineno}")
    assert offenders == []


def test_the_version_has_one_home() -> None:
    project = PYPROJECT["project"]
    assert "version" not in project and "version" in project["dynamic"]
    assert PYPROJECT["tool"]["setuptools"]["dynamic"]["version"]["attr"] == "optrack.__version__"
    assert importlib.metadata.version("optrack") == optrack.__version__
