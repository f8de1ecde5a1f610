"""``optrack eval``: detect and track a simulated recording, score it with CLEAR MOT."""

from __future__ import annotations

import json

import pytest

from optrack.cli import main
from optrack.recording import Recording, RecordingWriter, SensorInfo
from optrack.types import Intrinsics

KEYS = {"mota", "motp", "fp", "fn", "idsw", "precision", "recall", "frames", "fps"}


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory):
    """Two Kinect v2 sensors, 1.5 s of the crowd scenario, with ground truth."""
    from optrack.sim.recorder import write_recording
    from optrack.sim.world import Simulation

    path = tmp_path_factory.mktemp("eval") / "crowd"
    write_recording(Simulation("crowd", seed=3, sensors=2, seconds=1.5), path)
    return path


def _eval(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, dict]:
    code = main(["eval", *argv, "--json"])
    out = capsys.readouterr().out
    return code, (json.loads(out) if out.strip() else {})


def test_eval_prints_clear_mot_overall_and_per_sensor(recording, capsys) -> None:
    code, result = _eval(capsys, str(recording))
    assert code == 0
    assert KEYS <= set(result)
    assert result["frames"] == len(list(Recording(recording).ground_truth()))
    assert result["sensor_frames"] == 90
    assert 0.5 < result["mota"] <= 1.0, "seven people close to two sensors: most are tracked"
    assert 0.0 < result["motp"] < 0.3
    assert result["fps"] > 0
    assert set(result["sensors"]) == {"kinect2_0", "kinect2_1"}
    for sensor in result["sensors"].values():
        assert KEYS - {"fps"} <= set(sensor)
    assert result["appearance"] is False  # a network: appearance off by default


def test_eval_with_the_true_poses_as_calibration_file_scores_the_same(
    recording, capsys, tmp_path
) -> None:
    from optrack.calibration.files import CalibrationFile, SensorEntry, save_calibration

    rec = Recording(recording)
    calibration = CalibrationFile(
        sensors={
            sid: SensorEntry(world_T_camera=info.world_T_camera, model=info.model)
            for sid, info in rec.sensors.items()
        }
    )
    path = tmp_path / "network.yaml"
    save_calibration(path, calibration)
    _, default = _eval(capsys, str(recording))
    code, calibrated = _eval(capsys, str(recording), "--calibration", str(path))
    assert code == 0
    for key in ("mota", "idsw", "fp", "fn"):
        assert calibrated[key] == default[key]


def test_eval_refuses_a_recording_without_ground_truth(tmp_path, capsys) -> None:
    info = SensorInfo(id="cam", intrinsics=Intrinsics(200, 200, 79.5, 59.5, 160, 120))
    with RecordingWriter(tmp_path / "plain", [info]):
        pass
    code = main(["eval", str(tmp_path / "plain"), "--json"])
    captured = capsys.readouterr()
    assert code == 1
    assert captured.out == ""
    assert "has no ground truth" in captured.err and "optrack sim" in captured.err


def test_eval_refuses_a_config_with_an_unknown_stage(recording, tmp_path, capsys) -> None:
    config = tmp_path / "bad.yaml"
    config.write_text("trakcing:\n  gate_probability: 0.9\n")
    code = main(["eval", str(recording), "--config", str(config), "--json"])
    assert code == 1
    assert "unknown stages trakcing" in capsys.readouterr().err


def test_eval_takes_settings_from_a_config_file_and_the_command_line(
    recording, tmp_path, capsys
) -> None:
    config = tmp_path / "tracking.yaml"
    config.write_text(
        "tracking:\n  min_confidence_initialization: 100\n"
        "  min_confidence_weak_initialization: 100\n"
    )
    code, result = _eval(capsys, str(recording), "--config", str(config), "--appearance", "on")
    assert code == 0
    assert result["appearance"] is True
    assert result["tracks_started"] == 0  # no detection is that confident
    assert result["fn"] == result["objects"] > 0


def test_eval_detects_again_with_the_config_files_detection_values(
    recording, tmp_path, capsys
) -> None:
    config = tmp_path / "detection.yaml"
    _, default = _eval(capsys, str(recording))
    # Values for another sensor model leave these Kinect v2 sensors as they were.
    config.write_text("detection:\n  kinect1:\n    min_height: 2.2\n")
    code, other_model = _eval(capsys, str(recording), "--config", str(config))
    assert code == 0
    for key in ("mota", "idsw", "fp", "fn", "tracks_started"):
        assert other_model[key] == default[key]
    # Nobody here is 2.2 m tall: with that as the shortest person, nothing is detected.
    for section in ("  min_height: 2.2\n", "  kinect2:\n    min_height: 2.2\n"):
        config.write_text("detection:\n" + section)
        code, result = _eval(capsys, str(recording), "--config", str(config))
        assert code == 0
        assert result["tracks_started"] == 0
        assert result["fn"] == result["objects"] > 0


def test_eval_refuses_bad_detection_values_in_one_sentence(recording, tmp_path, capsys) -> None:
    config = tmp_path / "bad.yaml"
    config.write_text("detection:\n  kinect2:\n    max_distanse: 8\n")
    code = main(["eval", str(recording), "--config", str(config), "--json"])
    err = capsys.readouterr().err.strip()
    assert code == 1
    assert len(err.splitlines()) == 1
    assert "bad.yaml" in err and "under kinect2" in err and "max_distanse" in err
