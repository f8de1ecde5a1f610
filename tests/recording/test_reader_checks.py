"""A recording is read with the checks its writer makes (issue 20): time order, the
counts its manifest announces (a partial recording is read with one sentence saying how
much is missing) and index entries that stay inside the recording's folder."""

from __future__ import annotations

import json
import logging
import subprocess
import sys

import numpy as np
import pytest
import yaml

from optrack.recording import (
    GroundTruth,
    PersonTruth,
    Recording,
    RecordingError,
    RecordingWriter,
    SensorInfo,
)
from optrack.types import Intrinsics, RGBDFrame

K = Intrinsics(100, 100, 31.5, 23.5, 64, 48)


@pytest.fixture
def rec0(tmp_path):
    """Two sensors, 10 frames each at 10 Hz, ground truth at 20 Hz."""
    pose = ((1.0, 0.0, 0.0, 0.0), (0.0, -1.0, 0.0, 0.0), (0.0, 0.0, -1.0, 3.0), (0, 0, 0, 1.0))
    infos = [SensorInfo(sid, K, "kinect2", world_T_camera=pose, fps=10.0) for sid in "ab"]
    with RecordingWriter(tmp_path / "rec0", infos, ground_truth=True) as writer:
        for i in range(20):
            writer.write_ground_truth(
                GroundTruth(t=i / 20, people=[PersonTruth(id=0, x=0.0, y=0.0, height=1.7)])
            )
            if i % 2 == 0:
                for sid in ("a", "b"):
                    depth = np.full((48, 64), 2000 + i, np.uint16)
                    writer.write(RGBDFrame(depth, K, sid, i / 20, 0.001))
    return tmp_path / "rec0"


def lines(path) -> list[str]:
    return path.read_text().splitlines()


def rewrite(path, items: list[str]) -> None:
    path.write_text("".join(f"{item}\n" for item in items))


def test_the_writer_announces_its_counts_and_a_whole_recording_reads_without_a_word(rec0, caplog):
    manifest = yaml.safe_load((rec0 / "manifest.yaml").read_text())
    assert manifest["extra"]["frames"] == {"a": 10, "b": 10}
    assert manifest["extra"]["ground_truth_instants"] == 20
    with caplog.at_level(logging.WARNING, "optrack.recording"):
        recording = Recording(rec0)
        assert len(list(recording.frames())) == 20 and len(list(recording.ground_truth())) == 20
    assert caplog.records == []


@pytest.mark.parametrize("which", ["sensors/a/index.jsonl", "ground_truth.jsonl"])
def test_a_file_that_goes_back_in_time_is_refused(rec0, which):
    """Such a recording once scored MOTA 0.37 instead of 0.94 without a word."""
    items = lines(rec0 / which)
    items[3], items[7] = items[7], items[3]
    rewrite(rec0 / which, items)
    recording = Recording(rec0)
    with pytest.raises(RecordingError, match=r"line 5 is damaged: its time t=.* goes back from"):
        list(recording.frames() if "index" in which else recording.ground_truth())


def test_a_truncated_index_is_read_with_one_sentence_saying_how_much_is_missing(rec0, caplog):
    rewrite(rec0 / "sensors/a/index.jsonl", lines(rec0 / "sensors/a/index.jsonl")[:4])
    recording = Recording(rec0)
    with caplog.at_level(logging.WARNING, "optrack.recording"):
        assert len(list(recording.frames())) == 14
        assert recording.count("a") == 4  # said once per recording
    assert [r.getMessage() for r in caplog.records] == [
        f"recording {rec0} is partial: sensor 'a' holds 4 of the 10 frames its manifest "
        "announces (6 missing, 60%); only what is there is used."
    ]


def test_a_truncated_or_missing_ground_truth_says_how_much_is_missing(rec0, caplog):
    rewrite(rec0 / "ground_truth.jsonl", lines(rec0 / "ground_truth.jsonl")[:10])
    with caplog.at_level(logging.WARNING, "optrack.recording"):
        assert len(list(Recording(rec0).ground_truth())) == 10
        (rec0 / "ground_truth.jsonl").unlink()
        assert list(Recording(rec0).ground_truth()) == []
    assert [r.getMessage().split(": ")[1] for r in caplog.records] == [
        "the ground truth holds 10 of the 20 instants its manifest announces "
        "(10 missing, 50%); only what is there is used.",
        "the ground truth holds 0 of the 20 instants its manifest announces "
        "(20 missing, 100%); only what is there is used.",
    ]


@pytest.mark.parametrize("target", ["../../../../etc/passwd", "/etc/passwd", "depth/../../b/x"])
def test_index_entries_naming_files_outside_the_folder_are_refused(rec0, target):
    items = lines(rec0 / "sensors/a/index.jsonl")
    entry = json.loads(items[2])
    entry["depth"] = target
    items[2] = json.dumps(entry)
    rewrite(rec0 / "sensors/a/index.jsonl", items)
    with pytest.raises(RecordingError, match=f"frame 2 names depth image '{target}', outside"):
        list(Recording(rec0).frames(["a"]))


def test_a_partial_recording_is_scored_with_the_sentence_on_stderr(rec0):
    rewrite(rec0 / "sensors/b/index.jsonl", lines(rec0 / "sensors/b/index.jsonl")[:5])
    done = subprocess.run(
        [sys.executable, "-m", "optrack.cli", "eval", str(rec0), "--json"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["sensor_frames"] == 15
    assert (
        f"recording {rec0} is partial: sensor 'b' holds 5 of the 10 frames its manifest "
        "announces (5 missing, 50%)"
    ) in done.stderr
    assert "Traceback" not in done.stderr


@pytest.mark.parametrize(
    ("field", "value", "problem"),
    [
        ("id", "../../etc", "an id that cannot name a folder"),
        ("depth_scale", -1.0, "depth_scale -1.0 (metres per depth unit, above 0)"),
        ("depth_scale", float("nan"), "depth_scale nan"),
        ("fps", 0.0, "fps 0.0 (frames per second, above 0)"),
        (
            "world_T_camera",
            [[1, 0, 0, 1e308], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]],
            "a world_T_camera that moves 1e+308 m, beyond the 1000 m a site spans",
        ),
    ],
)
def test_a_manifest_sensor_the_writer_would_refuse_is_refused(rec0, field, value, problem):
    manifest = yaml.safe_load((rec0 / "manifest.yaml").read_text())
    manifest["sensors"][0][field] = value
    (rec0 / "manifest.yaml").write_text(yaml.safe_dump(manifest))
    with pytest.raises(RecordingError) as error:
        Recording(rec0)
    assert problem in str(error.value) and "is damaged: sensor" in str(error.value)
