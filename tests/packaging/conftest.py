"""Shared by the packaging tests: the wheel, built once per session into dist/."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

import optrack

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def wheel() -> Path:
    """dist/optrack-<version>-py3-none-any.whl, built from this checkout (as make wheel does)."""
    dist = REPO / "dist"
    path = dist / f"optrack-{optrack.__version__}-py3-none-any.whl"
    path.unlink(missing_ok=True)
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(dist), str(REPO)],
        check=True,
        cwd=REPO,
    )
    assert path.is_file()
    return path
