"""Values given on the command line are checked where they are parsed (issue 20): a
value outside its range gets one sentence naming it and the range, a non-zero exit, no
traceback, and nothing is written."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from optrack.cli import main
from optrack.recording import RecordingWriter, SensorInfo
from optrack.types import Intrinsics, RGBDFrame

K = Intrinsics(100, 100, 31.5, 23.5, 64, 48)


@pytest.fixture
def depth(tmp_path):
    path = tmp_path / "depth.png"
    cv2.imwrite(str(path), np.full((48, 64), 2000, np.uint16))
    return path


@pytest.fixture
def recording(tmp_path):
    with RecordingWriter(tmp_path / "rec0", [SensorInfo("cam", K)]) as writer:
        writer.write(RGBDFrame(np.full((48, 64), 2000, np.uint16), K, "cam", 0.0, 0.001))
    return tmp_path / "rec0"


def refused(capsys, argv: list[str], code: int, *words: str) -> str:
    try:
        status = main(argv)
    except SystemExit as stop:  # argparse refuses a value of the wrong type
        status = stop.code
    assert status == code
    err = capsys.readouterr().err
    assert "Traceback" not in err
    for word in words:
        assert word in err
    return err


@pytest.mark.parametrize("command", ["cloud", "detect"])
@pytest.mark.parametrize(
    "intrinsics", ["0,0,32,24", "nan,nan,32,24", "inf,100,32,24", "-300,-300,32,24", "100,-1,3,3"]
)
def test_intrinsics_that_no_camera_has_are_refused(tmp_path, capsys, depth, command, intrinsics):
    out = tmp_path / "o.pcd"
    argv = [command, str(depth), f"--intrinsics={intrinsics}"]
    if command == "cloud":
        argv += ["--out", str(out)]
    err = refused(capsys, argv, 1, f"intrinsics '{intrinsics}'", "focal lengths fx and fy above 0")
    assert err.count("\n") == 1
    assert not out.exists()


@pytest.mark.parametrize("command", ["cloud", "detect"])
@pytest.mark.parametrize("scale", ["-1", "nan", "0", "inf", "mm"])
def test_depth_scale_must_be_a_positive_finite_number(tmp_path, capsys, depth, command, scale):
    out = tmp_path / "o.pcd"
    argv = [command, str(depth), "--intrinsics=100,100,31.5,23.5", f"--depth-scale={scale}"]
    if command == "cloud":
        argv += ["--out", str(out)]
    refused(capsys, argv, 2, f"--depth-scale: '{scale}' must be a finite number above 0.")
    assert not out.exists()


def test_cloud_of_a_recording_refuses_bad_intrinsics_and_frames(tmp_path, capsys, recording):
    out = str(tmp_path / "o.pcd")
    refused(capsys, ["cloud", str(recording), "--intrinsics=0,0,3,3", "--out", out], 1, "'0,0,3,3'")
    refused(capsys, ["cloud", str(recording), "--depth-scale=nan", "--out", out], 2, "'nan'")
    refused(
        capsys,
        ["cloud", str(recording), "--frame=-1", "--out", out],
        2,
        "--frame: '-1' must be a whole number counted from 0",
    )
    assert not (tmp_path / "o.pcd").exists()


@pytest.mark.parametrize("frames", ["0", "-3", "two"])
def test_detect_frames_must_be_at_least_one(capsys, recording, frames):
    """``detect rec0 --frames 0`` once said the recording holds no depth frames."""
    err = refused(
        capsys,
        ["detect", str(recording), f"--frames={frames}"],
        2,
        f"--frames: '{frames}' must be a whole number of at least 1.",
    )
    assert "depth frames" not in err
