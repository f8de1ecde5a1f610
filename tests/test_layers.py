"""The house rule: imports run one way, down (docs/architecture.md, "Layers").

Every module of ``optrack`` and ``app`` is parsed with ``ast``; every import,
lazy ones inside functions included, must name a package of the same layer
(without a cycle) or of a lower one.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent

# Bottom to top. A package's own ``cli.py`` belongs to the ``cli`` layer.
LAYERS: list[set[str]] = [
    {
        "optrack.types",
        "optrack.geometry",
        "optrack.params",
        "optrack.errors",
        "optrack.io",
        "optrack.lazy",
        "optrack.resources",
    },
    {"optrack.recording", "optrack.net"},
    {
        "optrack.sensors",
        "optrack.detection",
        "optrack.tracking",
        "optrack.calibration",
        "optrack.outputs",
        "optrack.skeleton",
    },
    {"optrack.sim"},
    {"optrack.evaluation", "optrack.bench"},  # a bench measures a site as a black box
    {"optrack.runtime", "optrack.client"},
    {"optrack.cli"},
    {"app"},
]
RANK = {name: i for i, layer in enumerate(LAYERS) for name in layer}


def unit_of(module: str) -> str:
    """The layer unit a dotted module name belongs to (its package, or ``cli``)."""
    parts = module.split(".")
    if parts[0] == "app":
        return "app"
    if parts[-1] == "cli" or parts[-1] == "__main__":
        return "optrack.cli"
    if len(parts) == 1:
        return "optrack"
    unit = ".".join(parts[:2])
    if unit not in RANK:
        raise KeyError(
            f"{module} is in no layer; add its package to LAYERS in tests/test_layers.py"
        )
    return unit


def module_name(path: Path) -> str:
    rel = path.relative_to(REPO).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def imports_of(path: Path) -> list[tuple[int, str]]:
    """(line, dotted module) of every import in a file, relative ones resolved."""
    tree = ast.parse(path.read_text(), filename=str(path))
    here = module_name(path)
    package = here if path.name == "__init__.py" else here.rpartition(".")[0]
    found: list[tuple[int, str]] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")
                anchor = anchor[: len(anchor) - (node.level - 1)]
                base = ".".join(anchor + ([base] if base else []))
            # "from optrack import sim" imports the package optrack.sim
            for alias in node.names:
                found.append(
                    (node.lineno, f"{base}.{alias.name}" if base in ("optrack", "app") else base)
                )
    return [(line, name) for line, name in found if name.split(".")[0] in ("optrack", "app")]


def sources() -> list[Path]:
    return sorted(p for top in ("optrack", "app") for p in (REPO / top).rglob("*.py"))


def edges() -> list[tuple[str, int, str, str, str]]:
    out = []
    for path in sources():
        src = unit_of(module_name(path))
        for line, target in imports_of(path):
            try:
                dst = unit_of(target)
            except KeyError:
                dst = "optrack" if target == "optrack" else unit_of(target.rpartition(".")[0])
            if dst in ("optrack",) or src == dst:
                continue
            out.append((str(path.relative_to(REPO)), line, target, src, dst))
    return out


def test_every_package_is_in_a_layer():
    for path in sources():
        unit_of(module_name(path))


def test_no_import_runs_upward():
    upward = [
        f"{path}:{line} imports {target} ({src} is below {dst})"
        for path, line, target, src, dst in edges()
        if RANK[src] < RANK[dst]
    ]
    assert not upward, "imports that run upward:\n" + "\n".join(upward)


def test_no_cycle_between_packages():
    graph: dict[str, set[str]] = {}
    for _path, _line, _target, src, dst in edges():
        graph.setdefault(src, set()).add(dst)

    def reaches(a: str, b: str, seen: set[str]) -> bool:
        for nxt in graph.get(a, ()):
            if nxt == b or (nxt not in seen and reaches(nxt, b, seen | {nxt})):
                return True
        return False

    cycles = sorted(f"{a} <-> {b}" for a in graph for b in graph[a] if reaches(b, a, {b}))
    assert not cycles, "packages that import each other: " + ", ".join(cycles)


@pytest.mark.parametrize(
    ("module", "unit"),
    [("optrack.sim.body", "optrack.sim"), ("optrack.sim.cli", "optrack.cli"), ("app.main", "app")],
)
def test_units_are_read_as_the_rule_says(module, unit):
    assert unit_of(module) == unit


def test_no_module_over_600_lines():
    """A module that grows past 600 lines holds more than one concept: split it."""
    long = [
        f"{path.relative_to(REPO)}: {len(path.read_text().splitlines())} lines"
        for path in sources()
        if len(path.read_text().splitlines()) > 600
    ]
    assert not long, "modules over 600 lines:\n" + "\n".join(long)


def test_no_function_over_80_lines():
    """A function past 80 lines does several things: give each its name."""
    long = []
    for path in sources():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                length = (node.end_lineno or node.lineno) - node.lineno + 1
                if length > 80:
                    long.append(
                        f"{path.relative_to(REPO)}:{node.lineno} {node.name}: {length} lines"
                    )
    assert not long, "functions over 80 lines:\n" + "\n".join(long)
