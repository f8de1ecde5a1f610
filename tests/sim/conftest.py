"""Helpers for the simulator tests: small scenario files written on the fly."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from optrack.sim import Scenario, load_scenario


def write_scenario(path: Path, data: dict) -> Path:
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    return path


def wall_scenario(tmp_path: Path, distance: float, texture: float = 0.25) -> Scenario:
    """One sensor at 1.25 m looking level at a flat, textured wall ``distance`` metres away."""
    x_sensor = -7.5
    thickness = 0.2
    center = x_sensor + distance + thickness / 2
    data = {
        "description": "a flat wall in front of one sensor",
        "venue": {
            "size": [16.0, 8.0],
            "obstacles": [
                {
                    "kind": "box",
                    "at": [center, 0.0],
                    "size": [thickness, 7.0, 2.9],
                    "texture": texture,
                },
            ],
        },
        "sensors": {
            "count": 1,
            "poses": [{"at": [x_sensor, 0.0, 1.25], "look_at": [0.0, 0.0, 1.25]}],
        },
        "people": {"count": 0},
    }
    return load_scenario(write_scenario(tmp_path / f"wall_{distance:g}.yaml", data))


def person_scenario(tmp_path: Path) -> Scenario:
    """One sensor and one person walking slowly back and forth 3 m in front of it."""
    data = {
        "description": "one person in front of one sensor",
        "venue": {"size": [10.0, 8.0]},
        "sensors": {"count": 1, "poses": [{"at": [-4.5, 0.0, 2.2], "look_at": [0.0, 0.0, 0.9]}]},
        "people": {"count": 1, "routes": [[[-1.5, -0.3], [-1.5, 0.3]]]},
    }
    return load_scenario(write_scenario(tmp_path / "person.yaml", data))


@pytest.fixture
def scenario_dir(tmp_path: Path) -> Path:
    return tmp_path
