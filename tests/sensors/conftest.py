"""Fixtures for sensor tests: a small real recording written with RecordingWriter."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from optrack.recording import RecordingWriter, SensorInfo
from optrack.types import Intrinsics, RGBDFrame

K = Intrinsics(100.0, 100.0, 15.5, 11.5, 32, 24)


def write_recording(path: Path, sensors=("a", "b"), frames=10, period=0.1) -> Path:
    """A recording with ``frames`` frames per sensor, depth = 1000 + frame number (mm)."""
    infos = [
        SensorInfo(id=s, intrinsics=K, model="test", streams=["depth", "color"]) for s in sensors
    ]
    with RecordingWriter(path, infos) as writer:
        for i in range(frames):
            for j, sensor in enumerate(sensors):
                depth = np.full((24, 32), 1000 + i, dtype=np.uint16)
                color = np.zeros((24, 32, 3), dtype=np.uint8)
                color[..., j % 3] = 10 * i
                writer.write(
                    RGBDFrame(
                        depth,
                        K,
                        sensor_id=sensor,
                        timestamp=100.0 + i * period + j * 0.01,
                        depth_scale=0.001,
                        color=color,
                        seq=i,
                    )
                )
    return path


@pytest.fixture
def recording(tmp_path: Path) -> Path:
    return write_recording(tmp_path / "session")


@pytest.fixture
def single(tmp_path: Path) -> Path:
    return write_recording(tmp_path / "single", sensors=("cam",), frames=6)
