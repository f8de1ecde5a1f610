"""`optrack cloud`: depth image + intrinsics -> .pcd, checked against PCL's own clouds."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from optrack.cli import main
from optrack.io.pcd import read_pcd
from optrack.recording import RecordingWriter, SensorInfo
from optrack.types import Intrinsics, RGBDFrame

FRAMES = [
    "frame_20121214T142255.814212",
    "frame_20121214T142256.068683",
    "frame_20121214T142256.332395",
]


@pytest.mark.parametrize("frame", FRAMES)
def test_cloud_from_real_kinect_depth_matches_pcl(tmp_path, shared_data, frame):
    root = shared_data / "pcl" / "grabber_sequences"
    out = tmp_path / "x.pcd"
    code = main(
        [
            "cloud",
            str(root / "tiff" / f"{frame}_depth.tiff"),
            "--intrinsics",
            "525,525,320,240",
            "--depth-scale",
            "0.001",
            "--out",
            str(out),
        ]
    )
    assert code == 0
    ours = read_pcd(out).points
    reference = read_pcd(root / "pcd" / f"{frame}.pcd").points
    assert ours.shape == reference.shape == (480, 640, 3)
    ours_valid = np.isfinite(ours[..., 2])
    reference_valid = np.isfinite(reference[..., 2])
    assert ours_valid.sum() == reference_valid.sum() > 200_000
    np.testing.assert_array_equal(ours_valid, reference_valid)
    assert np.abs(ours[ours_valid] - reference[reference_valid]).max() < 1e-5


def test_console_script_writes_coloured_cloud_and_reports_json(tmp_path, shared_data):
    root = shared_data / "pcl" / "grabber_sequences" / "tiff"
    out = tmp_path / "c.pcd"
    optrack = Path(sys.executable).parent / "optrack"
    result = subprocess.run(
        [
            str(optrack),
            "cloud",
            str(root / f"{FRAMES[0]}_depth.tiff"),
            "--color",
            str(root / f"{FRAMES[0]}_rgb.tiff"),
            "--intrinsics",
            "525,525,320,240",
            "--out",
            str(out),
            "--json",
        ],
        capture_output=True,
        text=True,
        check=True,
    )
    import json

    report = json.loads(result.stdout)
    assert report["points"] == 271575 and report["color"] is True
    cloud = read_pcd(out)
    assert cloud.colors is not None and cloud.colors[np.isfinite(cloud.points[..., 2])].std() > 5


def test_cloud_from_a_recording_frame_uses_its_intrinsics(tmp_path):
    intrinsics = Intrinsics(100, 100, 31.5, 23.5, 64, 48)
    depth = np.full((48, 64), 2000, np.uint16)
    depth[0, :] = 0
    with RecordingWriter(tmp_path / "rec", [SensorInfo("cam", intrinsics)]) as writer:
        writer.write(RGBDFrame(depth, intrinsics, "cam", 0.0, 0.001))
    assert main(["cloud", str(tmp_path / "rec"), "--out", str(tmp_path / "r.pcd")]) == 0
    points = read_pcd(tmp_path / "r.pcd").points
    assert np.isnan(points[0]).all()
    np.testing.assert_allclose(
        points[23, 63], [(63 - 31.5) * 2 / 100, (23 - 23.5) * 2 / 100, 2.0], atol=1e-6
    )


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["{depth}", "--out", "{out}"], "needs --intrinsics"),
        (["{tmp}/missing.png", "--intrinsics", "1,1,0,0", "--out", "{out}"], "does not exist"),
        (["{tmp}", "--intrinsics", "1,1,0,0", "--out", "{out}"], "not an optrack recording"),
        (["{depth}", "--intrinsics", "525,525", "--out", "{out}"], "fx,fy,cx,cy"),
        (
            ["{depth}", "--intrinsics", "525,525,320,240", "--out", "{tmp}/x.ply"],
            "must name a .pcd",
        ),
    ],
)
def test_bad_cloud_input_gets_one_line(tmp_path, shared_data, capsys, args, message):
    depth = shared_data / "pcl" / "grabber_sequences" / "tiff" / f"{FRAMES[0]}_depth.tiff"
    filled = [a.format(depth=depth, out=tmp_path / "o.pcd", tmp=tmp_path) for a in args]
    assert main(["cloud", *filled]) == 1
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err and "Traceback" not in err
    assert not (tmp_path / "o.pcd").exists()
