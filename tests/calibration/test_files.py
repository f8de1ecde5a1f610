from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from optrack.calibration.files import (
    BoardEntry,
    CalibrationFile,
    CalibrationFileError,
    SensorEntry,
    load_calibration,
    load_network,
    new_calibration_id,
    openptrack_camera_poses,
    ros_static_transforms,
    save_calibration,
)
from optrack.cli import main
from optrack.geometry import invert, make_pose, pose_from_quaternion
from optrack.types import Intrinsics


def _pose(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return make_pose(Rotation.from_rotvec(rng.normal(size=3)), rng.normal(size=3) * 2)


def _matrix(pose):
    return tuple(tuple(float(v) for v in row) for row in pose)


@pytest.fixture
def calibration() -> CalibrationFile:
    return CalibrationFile(
        sensors={
            "cam0": SensorEntry(
                world_T_camera=_matrix(_pose(0)),
                intrinsics=Intrinsics(
                    525.0, 526.0, 319.5, 239.5, 640, 480, (0.1, -0.2, 0.0, 0.0, 0.01)
                ),
                model="kinect1",
                image="color",
                views=12,
                reprojection_rms_px=0.31,
            ),
            "cam1": SensorEntry(
                world_T_camera=_matrix(_pose(1)), refinement=_matrix(_pose(2)), views=3
            ),
        },
        id=new_calibration_id(),
        created="2025-01-02T03:04:05+00:00",
        board=BoardEntry(9, 6, 0.08, 0.005),
        quality={"reprojection_rms_px": 0.3, "floor_views": 2},
    )


def test_a_saved_calibration_reads_back_identical(tmp_path, calibration):
    path = tmp_path / "network.yaml"
    assert save_calibration(path, calibration) is None
    loaded = load_calibration(path)
    assert loaded == calibration
    np.testing.assert_allclose(loaded.pose("cam0"), _pose(0))
    network = load_network(path)
    np.testing.assert_allclose(network.pose("cam1"), _pose(1))
    assert network.sensors["cam0"].intrinsics.fx == 525.0
    text = path.read_text()
    assert text.startswith("format: optrack-calibration\nversion: 1\nid: ")


def test_saving_again_keeps_the_previous_file_as_backup(tmp_path, calibration):
    path = tmp_path / "network.yaml"
    save_calibration(path, calibration)
    first = path.read_bytes()
    changed = calibration.with_poses({"cam0": _pose(5)})
    backup = save_calibration(path, changed)
    assert backup == tmp_path / "network.yaml.bak"
    assert backup.read_bytes() == first
    np.testing.assert_allclose(load_calibration(path).pose("cam0"), _pose(5))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["network.yaml", "network.yaml.bak"]


def _write(tmp_path, mutate) -> object:
    path = tmp_path / "bad.yaml"
    good = tmp_path / "good.yaml"
    save_calibration(
        good,
        CalibrationFile(sensors={"cam0": SensorEntry(world_T_camera=_matrix(_pose(0)))}),
    )
    data = yaml.safe_load(good.read_text())
    mutate(data)
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.parametrize(
    ("mutate", "words"),
    [
        (lambda d: d.update(version=7), "version 7"),
        (lambda d: d.update(format="something"), "not an optrack calibration"),
        (lambda d: d["sensors"]["cam0"]["world_T_camera"][0].__setitem__(0, 2.0), "not a rigid"),
        (lambda d: d["sensors"]["cam0"].update(refinement=np.eye(4).tolist()[:3]), "damaged"),
        (lambda d: d.update(sensors={}), "no sensors"),
        (
            lambda d: d["sensors"]["cam0"].update(intrinsics={"fx": -1, "fy": 1, "cx": 0, "cy": 0}),
            "damaged",
        ),
        (lambda d: d.update(ground=[0, 0, 2, 0]), "unit normal"),
        # issue 20: non-finite or absurd values
        (
            lambda d: d["sensors"]["cam0"]["world_T_camera"][0].__setitem__(3, 1e308),
            "world_T_camera moves 1e[+]308 m, beyond the 1000 m a site spans",
        ),
        (
            lambda d: d["sensors"]["cam0"]["world_T_camera"][2].__setitem__(3, -1500.0),
            "world_T_camera moves 1500 m, beyond the 1000 m",
        ),
        (
            lambda d: d["sensors"]["cam0"]["world_T_camera"][1].__setitem__(3, float("nan")),
            "world_T_camera must be a finite 4x4 matrix",
        ),
        (
            lambda d: d.update(world="camera:nosuch"),
            r"world 'camera:nosuch' must be floor, points or camera:<id> of one of its sensors "
            r"\(cam0\)",
        ),
        (lambda d: d.update(world="ceiling"), "world 'ceiling' must be floor, points"),
        (
            lambda d: d["sensors"]["cam0"].update(
                intrinsics={"fx": 500, "fy": 500, "cx": 319.5, "cy": 239.5, "width": 0}
            ),
            "intrinsics are for an image of 0x0 pixels; width and height must be 1 or more",
        ),
        (
            lambda d: d["sensors"]["cam0"].update(
                intrinsics={"fx": float("inf"), "fy": 500, "cx": 319.5, "cy": 239.5}
            ),
            "intrinsics fx must be a finite number",
        ),
        (lambda d: d.update(ground=[0, 0, float("nan"), 0]), "unit normal"),
        (
            lambda d: d.update(board={"cols": 9, "rows": 6, "square": float("nan")}),
            "is no checkerboard",
        ),
    ],
)
def test_a_bad_file_is_refused_in_one_sentence(tmp_path, mutate, words):
    path = _write(tmp_path, mutate)
    with pytest.raises(CalibrationFileError, match=words) as error:
        load_calibration(path)
    assert "\n" not in str(error.value)


def test_a_missing_file_and_broken_yaml_say_what_to_do(tmp_path):
    with pytest.raises(CalibrationFileError, match="calibrate network"):
        load_calibration(tmp_path / "nothing.yaml")
    broken = tmp_path / "broken.yaml"
    broken.write_text("format: [unclosed\n")
    with pytest.raises(CalibrationFileError, match="not valid YAML"):
        load_calibration(broken)


def test_a_missing_sensor_is_named(calibration):
    with pytest.raises(CalibrationFileError, match="'cam7'"):
        calibration.require(["cam0", "cam7"])


def test_openptrack_export_has_poses_and_their_inverses(calibration):
    data = yaml.safe_load(openptrack_camera_poses(calibration))
    assert isinstance(data["calibration_id"], int) and data["calibration_id"] > 0
    for sid, entry in calibration.sensors.items():
        pose = data["poses"][sid]
        inverse = data["inverse_poses"][sid]
        as_matrix = pose_from_quaternion(
            [pose["rotation"][k] for k in "xyzw"], [pose["translation"][k] for k in "xyz"]
        )
        np.testing.assert_allclose(as_matrix, entry.pose, atol=1e-7)
        inverse_matrix = pose_from_quaternion(
            [inverse["rotation"][k] for k in "xyzw"], [inverse["translation"][k] for k in "xyz"]
        )
        np.testing.assert_allclose(inverse_matrix, invert(entry.pose), atol=1e-7)


def test_ros_export_lists_one_static_transform_per_sensor(calibration):
    data = yaml.safe_load(ros_static_transforms(calibration))
    transforms = {t["child"]: t for t in data["transforms"]}
    assert set(transforms) == {"cam0_optical_frame", "cam1_optical_frame"}
    cam1 = transforms["cam1_optical_frame"]
    np.testing.assert_allclose(
        pose_from_quaternion(cam1["rotation_xyzw"], cam1["translation"]), _pose(1), atol=1e-7
    )
    assert cam1["command"].startswith("ros2 run tf2_ros static_transform_publisher --x ")
    assert "--frame-id world --child-frame-id cam1_optical_frame" in cam1["command"]


def test_export_cli_writes_the_chosen_format(tmp_path, calibration, capsys):
    path = tmp_path / "network.yaml"
    save_calibration(path, calibration)
    out = tmp_path / "camera_poses.yaml"
    code = main(
        ["calibrate", "export", str(path), "--format", "openptrack", "--out", str(out), "--json"]
    )
    assert code == 0
    assert json.loads(capsys.readouterr().out)["sensors"] == ["cam0", "cam1"]
    assert "inverse_poses" in yaml.safe_load(out.read_text())
    code = main(
        ["calibrate", "export", str(tmp_path / "none.yaml"), "--format", "ros", "--out", str(out)]
    )
    assert code == 1
    assert "does not exist" in capsys.readouterr().err


def test_a_calibration_that_no_site_has_is_not_written(tmp_path, calibration):
    """Saving says what is wrong with the calibration being written, not with a file to
    restore (issue 20: a NaN from ``calibrate ground --points`` blamed the .bak file)."""
    far = _pose(0)
    far[:3, 3] = (2000.0, 0.0, 0.0)
    path = tmp_path / "network.yaml"
    with pytest.raises(CalibrationFileError) as error:
        save_calibration(path, calibration.with_poses({"cam0": far}))
    assert str(error.value) == (
        f"the calibration for {path}: sensor 'cam0' world_T_camera moves 2000 m, beyond the "
        "1000 m a site spans; nothing was written; check what it was made from."
    )
    assert not path.exists()
