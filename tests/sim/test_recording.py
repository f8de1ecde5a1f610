"""``optrack sim``: a recording with ground truth and the true calibration; the same seed
gives the same recording."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from optrack.cli import main
from optrack.recording import Recording


def _sim(out: Path, *extra: str) -> tuple[int, dict]:
    import contextlib
    import io

    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout):
        code = main(["sim", "mixed", "--out", str(out), "--seconds", "0.25", "--json", *extra])
    text = stdout.getvalue()
    assert text.count("\n") == 1, "exactly one JSON object on stdout"
    return code, json.loads(text)


def test_sim_writes_a_recording_with_ground_truth_and_true_poses(tmp_path, capsys):
    code, result = _sim(tmp_path / "rec", "--sensors", "2", "--people", "4", "--seed", "1")
    assert code == 0
    assert result["sensors"] == 2 and result["seconds"] == 0.25
    recording = Recording(tmp_path / "rec")
    assert result["frames"] == sum(recording.count(s) for s in recording.sensor_ids) > 10
    assert recording.has_ground_truth
    for info in recording.sensors.values():
        pose = np.array(info.world_T_camera)
        assert pose[2, 3] == pytest.approx(2.6)  # mounted high
        assert pose[:3, 2] @ [0.0, 0.0, 1.0] < -0.3  # and tilted down
        assert info.model == "kinect2" and info.fps == 30.0
        assert set(info.streams) == {"depth", "color", "infrared"}
    frames = list(recording.frames())
    assert all(f.color is not None and f.infrared is not None for f in frames)
    assert [f.timestamp for f in frames] == sorted(f.timestamp for f in frames)
    truth = list(recording.ground_truth())
    assert len(truth) == result["frames"]  # sensors are not in sync: one instant per frame
    assert all(len(t.people) >= 3 for t in truth)
    assert all(set(p.visible) == set(recording.sensor_ids) for t in truth for p in t.people)
    assert "sim mixed" in capsys.readouterr().err  # the progress bar


def test_same_seed_gives_the_same_recording_and_another_seed_another(tmp_path):
    paths = []
    for name, seed in (("a", "3"), ("b", "3"), ("c", "4")):
        code, _ = _sim(
            tmp_path / name, "--seed", seed, "--sensors", "2", "--sensor-model", "kinect1"
        )
        assert code == 0
        paths.append(tmp_path / name)

    def contents(root: Path) -> dict[str, bytes]:
        files = {}
        for path in sorted(root.rglob("*")):
            if path.is_file():
                data = path.read_bytes()
                if path.name == "manifest.yaml":
                    manifest = yaml.safe_load(data)
                    manifest.pop("created")
                    data = json.dumps(manifest, sort_keys=True).encode()
                files[str(path.relative_to(root))] = data
        return files

    a, b, c = (contents(p) for p in paths)
    assert a == b
    assert a["ground_truth.jsonl"] != c["ground_truth.jsonl"]


@pytest.mark.parametrize("model", ["sr4500", "stereo"])
def test_other_sensor_models_record_their_streams(tmp_path, model):
    code, result = _sim(tmp_path / model, "--sensors", "1", "--sensor-model", model)
    assert code == 0
    recording = Recording(tmp_path / model)
    info = next(iter(recording.sensors.values()))
    frame = next(recording.frames())
    if model == "sr4500":
        assert info.fps == 13.0 and frame.confidence is not None and frame.color is None
        assert frame.depth.shape == (144, 176)
    else:
        assert frame.color.shape == (480, 640, 3)


def test_output_directory_must_be_new(tmp_path, capsys):
    out = tmp_path / "taken"
    out.mkdir()
    (out / "something").write_text("x")
    assert main(["sim", "mixed", "--out", str(out), "--seconds", "0.1"]) == 1
    assert "already exists" in capsys.readouterr().err


def test_config_file_sets_sensor_parameters(tmp_path):
    config = tmp_path / "params.yaml"
    config.write_text("sim_kinect1:\n  resolution: 320x240\n", encoding="utf-8")
    code, _ = _sim(
        tmp_path / "low", "--sensors", "1", "--sensor-model", "kinect1", "--config", str(config)
    )
    assert code == 0
    frame = next(Recording(tmp_path / "low").frames())
    assert frame.depth.shape == (240, 320) and frame.color.shape == (240, 320, 3)
