"""``calibrate ground --points``: a point's pixel outside the depth image, or a value that
is not a finite number, is refused with one sentence naming the point, the value and the
range; nothing is written (issue 20)."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from optrack.calibration.files import CalibrationFile, save_calibration
from optrack.cli import main
from optrack.recording import RecordingWriter, SensorInfo
from optrack.types import Intrinsics, RGBDFrame

K = Intrinsics(100, 100, 31.5, 23.5, 64, 48)


@pytest.fixture
def site(tmp_path):
    info = SensorInfo("cam", K)
    with RecordingWriter(tmp_path / "rec0", [info]) as writer:
        writer.write(RGBDFrame(np.full((48, 64), 2000, np.uint16), K, "cam", 0.0, 0.001))
    calibration = tmp_path / "network.yaml"
    save_calibration(calibration, CalibrationFile.of_poses({"cam": np.eye(4)}, {"cam": info}))
    return tmp_path / "rec0", calibration


def ground(capsys, site, tmp_path, points):
    recording, calibration = site
    points_file = tmp_path / "points.yaml"
    points_file.write_text(yaml.safe_dump({"points": points}))
    out = tmp_path / "out.yaml"
    argv = ["calibrate", "ground", str(recording), "--calibration", str(calibration)]
    code = main([*argv, "--points", str(points_file), "--out", str(out)])
    err = capsys.readouterr().err
    assert "Traceback" not in err and err.count("\n") == 1
    assert not out.exists() and not (tmp_path / "out.yaml.bak").exists()
    return code, err


CLICKS = [
    {"sensor": "cam", "u": u, "v": v, "world": [u / 10, v / 10, 0.0]}
    for u, v in ((5, 5), (50, 10), (20, 40))
]


def test_clicked_pixels_inside_the_image_give_a_world(site, tmp_path, capsys):
    recording, calibration = site
    points_file = tmp_path / "points.yaml"
    points_file.write_text(yaml.safe_dump({"points": CLICKS}))
    out = tmp_path / "out.yaml"
    argv = ["calibrate", "ground", str(recording), "--calibration", str(calibration)]
    assert main([*argv, "--points", str(points_file), "--out", str(out)]) == 0
    assert out.exists()


@pytest.mark.parametrize(
    ("key", "value", "sentence"),
    [
        ("u", 9999, "point 2's u must be a number from 0 to 63; got 9999."),
        ("v", -5, "point 2's v must be a number from 0 to 47; got -5."),
        ("u", float("nan"), "point 2's u must be a number from 0 to 63; got nan."),
        ("v", "top", "point 2's v must be a number from 0 to 47; got 'top'."),
        ("frame", -1, "point 2's frame must be a number of 0 or more; got -1."),
    ],
)
def test_a_pixel_outside_the_depth_image_is_refused(site, tmp_path, capsys, key, value, sentence):
    """``u: 9999`` was an IndexError; ``v: -5`` wrapped to the last row and wrote a file."""
    points = [dict(p) for p in CLICKS]
    points[1][key] = value
    code, err = ground(capsys, site, tmp_path, points)
    assert code == 1 and sentence in err


@pytest.mark.parametrize("key", ["world", "camera"])
@pytest.mark.parametrize("value", [[0.0, float("nan"), 1.0], [1.0, 2.0], "here"])
def test_a_world_or_camera_point_that_is_not_three_finite_numbers_is_refused(
    site, tmp_path, capsys, key, value
):
    """A NaN once reached the fit and the message blamed the output file ("restore the
    .bak file") that did not exist yet."""
    points = [dict(p) for p in CLICKS]
    points[2][key] = value
    code, err = ground(capsys, site, tmp_path, points)
    assert code == 1
    assert f"point 3's {key} must be three finite numbers x, y, z in metres" in err
    assert ".bak" not in err
