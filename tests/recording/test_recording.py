import os
import signal
import subprocess
import sys
import textwrap
import time
import tracemalloc

import numpy as np
import pytest
import yaml

from optrack.params import REGISTRY
from optrack.recording import (
    BoardTruth,
    GroundTruth,
    PersonTruth,
    Recording,
    RecordingError,
    RecordingWriter,
    SensorInfo,
)
from optrack.types import Intrinsics, RGBDFrame

K = Intrinsics(200, 200, 79.5, 59.5, 160, 120)


def make_frame(sensor: str, t: float, seed: int, color=True, ir=False) -> RGBDFrame:
    rng = np.random.default_rng(seed)
    depth = rng.integers(0, 8000, (120, 160), dtype=np.uint16)
    return RGBDFrame(
        depth,
        K,
        sensor_id=sensor,
        timestamp=t,
        depth_scale=0.001,
        color=rng.integers(0, 255, (120, 160, 3), dtype=np.uint8) if color else None,
        infrared=rng.integers(0, 65535, (120, 160), dtype=np.uint16) if ir else None,
        confidence=rng.integers(0, 255, (120, 160), dtype=np.uint8) if ir else None,
    )


def sensors(*ids: str) -> list[SensorInfo]:
    pose = ((1.0, 0.0, 0.0, 0.5), (0.0, 1.0, 0.0, 0.0), (0.0, 0.0, 1.0, 2.5), (0.0, 0.0, 0.0, 1.0))
    return [
        SensorInfo(i, K, model="kinect2", uri=f"sim://mixed/{n}", world_T_camera=pose, fps=30.0)
        for n, i in enumerate(ids)
    ]


def test_round_trip_keeps_depth_exactly_and_merges_sensors_in_time_order(tmp_path):
    out = tmp_path / "session"
    params = REGISTRY["recording"].create({"color_format": "png"})
    written = []
    with RecordingWriter(out, sensors("a", "b"), params=params, source="test") as writer:
        for i in range(5):
            for sid, offset in (("a", 0.004), ("b", 0.0)):
                frame = make_frame(sid, i / 30 + offset, seed=len(written), ir=sid == "b")
                writer.write(frame)
                written.append(frame)
    recording = Recording(out)
    assert recording.sensor_ids == ["a", "b"]
    assert recording.sensors["a"].world_T_camera[2][3] == 2.5
    frames = list(recording.frames())
    assert [f.timestamp for f in frames] == sorted(f.timestamp for f in written)
    by_key = {(f.sensor_id, f.timestamp): f for f in written}
    for frame in frames:
        original = by_key[(frame.sensor_id, frame.timestamp)]
        np.testing.assert_array_equal(frame.depth, original.depth)
        np.testing.assert_array_equal(frame.color, original.color)  # PNG is lossless
        assert frame.intrinsics == K and frame.depth_scale == 0.001
        if frame.sensor_id == "b":
            np.testing.assert_array_equal(frame.infrared, original.infrared)
            np.testing.assert_array_equal(frame.confidence, original.confidence)
        else:
            assert frame.infrared is None
    assert recording.count("a") == 5
    assert yaml.safe_load((out / "manifest.yaml").read_text())["extra"]["frames"] == {
        "a": 5,
        "b": 5,
    }


def test_jpeg_colour_is_close_to_the_original(tmp_path):
    smooth = np.dstack([np.tile(np.linspace(0, 255, 160, dtype=np.uint8), (120, 1))] * 3)
    frame = RGBDFrame(np.full((120, 160), 1000, np.uint16), K, "a", 0.0, 0.001, color=smooth)
    with RecordingWriter(tmp_path / "r", sensors("a")) as writer:
        writer.write(frame)
    back = Recording(tmp_path / "r").frame("a", 0)
    assert np.abs(back.color.astype(int) - smooth).mean() < 2.0


def test_ground_truth_streams_back_in_order(tmp_path):
    pose = tuple(tuple(float(v) for v in row) for row in np.eye(4))
    with RecordingWriter(tmp_path / "r", sensors("a"), ground_truth=True) as writer:
        for i in range(3):
            writer.write_ground_truth(
                GroundTruth(
                    t=i * 0.1,
                    people=[
                        PersonTruth(
                            1,
                            0.5 * i,
                            1.0,
                            1.8,
                            visible={"a": 0.7},
                            joints={"head": (0.5 * i, 1.0, 1.7)},
                        )
                    ],
                    boards=[BoardTruth(pose, cols=9, rows=6, square=0.1, on_floor=True)]
                    if i == 2
                    else [],
                )
            )
        with pytest.raises(RecordingError, match="older than the previous"):
            writer.write_ground_truth(GroundTruth(t=0.05))
    truth = list(Recording(tmp_path / "r").ground_truth())
    assert [g.t for g in truth] == [0.0, 0.1, 0.2]
    assert truth[1].people[0].x == 0.5 and truth[1].people[0].visible == {"a": 0.7}
    assert truth[2].boards[0].on_floor and truth[2].boards[0].cols == 9


def test_writer_refuses_to_overwrite_and_to_misorder(tmp_path):
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "precious.txt").write_text("keep me")
    with pytest.raises(RecordingError, match="not an empty directory.*nothing was overwritten"):
        RecordingWriter(tmp_path / "full", sensors("a"))
    assert (tmp_path / "full" / "precious.txt").read_text() == "keep me"
    with RecordingWriter(tmp_path / "r", sensors("a")) as writer:
        writer.write(make_frame("a", 1.0, 0))
        with pytest.raises(RecordingError, match="older than the previous one"):
            writer.write(make_frame("a", 0.5, 1))
        with pytest.raises(RecordingError, match="does not declare"):
            writer.write(make_frame("zz", 2.0, 2))
    with pytest.raises(RecordingError, match="cannot name a folder"):
        RecordingWriter(tmp_path / "r2", sensors("../evil"))


WRITER_SCRIPT = textwrap.dedent(
    """
    import sys, numpy as np
    from optrack.recording import RecordingWriter, SensorInfo
    from optrack.types import Intrinsics, RGBDFrame
    K = Intrinsics(200, 200, 79.5, 59.5, 160, 120)
    rng = np.random.default_rng(0)
    writer = RecordingWriter(sys.argv[1], [SensorInfo("a", K), SensorInfo("b", K)])
    i = 0
    while True:  # until killed
        for sid in "ab":
            depth = np.full((120, 160), 500 + i % 7000, np.uint16)
            writer.write(RGBDFrame(depth, K, sid, i / 30, 0.001, color=rng.integers(0, 255, (120, 160, 3), dtype=np.uint8)))
        i += 1
    """
)


def test_writer_killed_midway_leaves_every_indexed_frame_readable(tmp_path):
    out = tmp_path / "killed"
    process = subprocess.Popen([sys.executable, "-c", WRITER_SCRIPT, str(out)])
    index = out / "sensors" / "a" / "index.jsonl"
    deadline = time.monotonic() + 60
    try:
        while time.monotonic() < deadline:
            if index.exists() and index.read_bytes().count(b"\n") >= 40:
                break
            time.sleep(0.05)
        else:
            pytest.fail("the writer did not index 40 frames in 60 s")
    finally:
        process.send_signal(signal.SIGKILL)
        process.wait()
    recording = Recording(out)
    frames = list(recording.frames())
    assert len(frames) >= 80
    for frame in frames:
        assert frame.depth.shape == (120, 160) and frame.color.shape == (120, 160, 3)
        assert int(frame.depth[0, 0]) == 500 + round(frame.timestamp * 30) % 7000


def test_a_last_index_line_cut_short_is_ignored(tmp_path):
    with RecordingWriter(tmp_path / "r", sensors("a")) as writer:
        for i in range(3):
            writer.write(make_frame("a", i, i))
    with (tmp_path / "r" / "sensors" / "a" / "index.jsonl").open("ab") as handle:
        handle.write(b'{"seq":3,"t":3.0,"dep')
    assert [f.seq for f in Recording(tmp_path / "r").frames()] == [0, 1, 2]


def test_foreign_and_damaged_directories_get_a_clear_error(tmp_path):
    with pytest.raises(RecordingError, match="does not exist"):
        Recording(tmp_path / "nowhere")
    (tmp_path / "photos").mkdir()
    with pytest.raises(RecordingError, match="not an optrack recording.*no manifest.yaml"):
        Recording(tmp_path / "photos")
    (tmp_path / "photos" / "manifest.yaml").write_text("format: something-else\n")
    with pytest.raises(RecordingError, match="not an optrack recording"):
        Recording(tmp_path / "photos")
    (tmp_path / "photos" / "manifest.yaml").write_text(
        "format: optrack-recording\nversion: 99\nsensors: []\n"
    )
    with pytest.raises(RecordingError, match="format version 99"):
        Recording(tmp_path / "photos")
    (tmp_path / "photos" / "manifest.yaml").write_text(
        "format: optrack-recording\nversion: 1\nsensors: [{id: a}]\n"
    )
    with pytest.raises(RecordingError, match="damaged"):
        Recording(tmp_path / "photos")

    with RecordingWriter(tmp_path / "r", sensors("a")) as writer:
        writer.write(make_frame("a", 0.0, 0))
    os.remove(tmp_path / "r" / "sensors" / "a" / "depth" / "00000000.png")
    with pytest.raises(RecordingError, match="damaged: sensors/a/depth/00000000.png is missing"):
        list(Recording(tmp_path / "r").frames())
    (tmp_path / "r" / "sensors" / "a" / "index.jsonl").write_bytes(b"not json\n")
    with pytest.raises(RecordingError, match="line 1 is damaged"):
        list(Recording(tmp_path / "r").frames())


def test_reading_streams_in_constant_memory(tmp_path):
    big = Intrinsics(500, 500, 319.5, 239.5, 640, 480)
    info = [SensorInfo("a", big), SensorInfo("b", big)]
    params = REGISTRY["recording"].create({"png_compression": 0})
    depth = np.full((480, 640), 1234, np.uint16)
    with RecordingWriter(tmp_path / "r", info, params=params) as writer:
        for i in range(60):
            for sid in "ab":
                writer.write(RGBDFrame(depth, big, sid, i / 30, 0.001))
    frame_bytes = depth.nbytes
    tracemalloc.start()
    count = 0
    for frame in Recording(tmp_path / "r").frames():
        count += int(frame.depth[0, 0] == 1234)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert count == 120
    assert peak < 10 * frame_bytes  # 120 frames of 600 kB went through; a handful were ever held
