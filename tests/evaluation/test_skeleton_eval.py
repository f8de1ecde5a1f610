"""``optrack eval --skeleton``: the marker error figures by hand, and end to end on a short
simulated recording of a real CMU clip."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from optrack.cli import main
from optrack.evaluation.skeleton import (
    initialisation_times,
    marker_errors,
    score_initialisation,
    score_markers,
)
from optrack.skeleton.joints import MARKERS

FIGURES = {"mean_error_m", "markers", "pct_under_0_10", "pct_under_0_15", "pct_under_0_20"}
FIGURES |= {"lost_pct", "fps"}


def _truth(frames: int = 10) -> np.ndarray:
    return np.random.default_rng(0).uniform(-2.0, 2.0, (frames, len(MARKERS), 3))


def test_one_marker_off_by_12_cm_gives_the_expected_figures() -> None:
    truth = _truth()
    estimate = truth.copy()
    estimate[:, MARKERS.index("left_wrist")] += (0.0, 0.12, 0.0)
    figures = score_markers(marker_errors(truth, estimate))
    assert figures["mean_error_m"] == pytest.approx(0.03)  # 0.12 on one marker of four
    assert figures["markers"]["left_wrist"]["mean_error_m"] == pytest.approx(0.12)
    assert figures["markers"]["right_ankle"]["mean_error_m"] == 0.0
    assert figures["pct_under_0_10"] == 75.0
    assert figures["pct_under_0_15"] == 100.0
    assert figures["pct_under_0_20"] == 100.0
    assert figures["lost_pct"] == 0.0
    assert figures["frames"] == 10


def test_lost_is_an_error_of_0_2_m_or_more_and_a_missing_estimate() -> None:
    truth = _truth()
    estimate = truth.copy()
    estimate[:5, MARKERS.index("right_ankle")] += (0.3, 0.0, 0.4)  # 0.5 m in half the frames
    estimate[0, MARKERS.index("right_wrist")] = np.nan  # no estimate yet
    figures = score_markers(marker_errors(truth, estimate))
    assert figures["lost_pct"] == 15.0  # 6 of 40 marker-frames
    assert figures["pct_under_0_20"] == 85.0
    assert figures["markers"]["right_ankle"]["lost_pct"] == 50.0
    assert figures["markers"]["right_wrist"]["lost_pct"] == 10.0
    assert figures["markers"]["right_wrist"]["mean_error_m"] == 0.0  # over the 9 estimated
    assert figures["mean_error_m"] == pytest.approx(2.5 / 39, abs=1e-4)


@pytest.fixture(scope="module")
def mocap_recording(tmp_path_factory: pytest.TempPathFactory, shared_data):
    """1 s of one person walking (CMU 16_27) before two Kinect v2."""
    from optrack.sim.recorder import write_recording
    from optrack.sim.world import Simulation

    path = tmp_path_factory.mktemp("skeleton") / "walk"
    clip = str(shared_data / "mocap" / "cmu_16_27_walk_turn_left.bvh")
    sim = Simulation("mocap", people=1, sensors=2, seconds=1.0, clips=[clip], seed=1)
    write_recording(sim, path)
    return path


def test_eval_skeleton_end_to_end(mocap_recording, capsys) -> None:
    code = main(["eval", str(mocap_recording), "--skeleton", "--json"])
    assert code == 0
    result = json.loads(capsys.readouterr().out)
    assert "mota" in result  # the tracking figures are still there
    skeleton = result["skeleton"]
    assert FIGURES <= set(skeleton)
    assert set(skeleton["markers"]) == set(MARKERS)
    assert skeleton["frames"] == 30  # one person at the first sensor's 30 Hz for 1 s
    assert skeleton["people"] == 1 and len(skeleton["sensors"]) == 2
    assert all(math.isfinite(skeleton[k]) for k in FIGURES - {"markers"})
    assert skeleton["fps"] > 0
    assert skeleton["pct_under_0_20"] + skeleton["lost_pct"] == pytest.approx(100.0)
    assert skeleton["mean_error_m"] < 0.4  # loose: the wrong frame or person is metres off
    init = skeleton["initialisation"]
    assert set(init) == {"init_s", "init_s_median", "init_s_max", "init_within_1s"}
    assert len(init["init_s"]) == 1 and init["init_within_1s"] in (0.0, 1.0)


def test_eval_skeleton_refuses_a_recording_without_joints(tmp_path, capsys) -> None:
    from optrack.recording import GroundTruth, RecordingWriter, SensorInfo
    from optrack.recording.format import PersonTruth
    from optrack.types import Intrinsics

    info = SensorInfo(id="cam", intrinsics=Intrinsics(200, 200, 79.5, 59.5, 160, 120))
    with RecordingWriter(tmp_path / "floor", [info], ground_truth=True) as writer:
        writer.write_ground_truth(GroundTruth(t=0.0, people=[PersonTruth(0, 1.0, 2.0, 1.7)]))
    code = main(["eval", str(tmp_path / "floor"), "--skeleton", "--json"])
    captured = capsys.readouterr()
    assert code == 1
    assert captured.out == ""
    err = captured.err.strip()
    assert "no joint positions" in err and "optrack sim mocap" in err
    assert len(err.splitlines()) == 1


def test_init_s_is_when_the_error_stays_under_0_1_m_for_half_a_second() -> None:
    """Person 3 is off for 10 frames, under 0.1 m from frame 10 but for a blip at frame
    20, then under it to the end: tracked at frame 21 (0.7 s at 30 Hz). Person 5 settles
    at frame 4, but a wrist without an estimate at frame 6 counts as lost: frame 7.
    Person 8 never settles."""
    frames, rate = 60, 30.0
    t = np.arange(frames) / rate + 2.0  # their first frame is at 2 s
    first = np.full((frames, len(MARKERS)), 0.05)
    first[:10] = 0.3
    first[20, 0] = 0.3  # one marker 0.3 m: the frame's mean 0.11 m
    second = np.full((20, len(MARKERS)), 0.02)
    second[:4] = 0.5
    second[6, 1] = np.nan
    third = np.full((frames, len(MARKERS)), 0.15)
    errors = np.concatenate([first, second, third])
    people = np.repeat([3, 5, 8], [frames, 20, frames])
    stamps = np.concatenate([t, t[:20] + 1.0, t])
    times = initialisation_times(errors, people, stamps)
    assert times == {
        3: pytest.approx(21 / rate, abs=1e-4),
        5: pytest.approx(7 / rate, abs=1e-4),
        8: None,
    }
    figures = score_initialisation(times)
    assert figures["init_s"] == {"3": times[3], "5": times[5], "8": None}
    assert figures["init_s_median"] == pytest.approx(14 / rate, abs=1e-4)
    assert figures["init_s_max"] == pytest.approx(21 / rate, abs=1e-4)
    assert figures["init_within_1s"] == pytest.approx(2 / 3, abs=1e-4)  # the third never is


def test_init_s_needs_the_whole_half_second_when_the_frames_go_on() -> None:
    """Under 0.1 m for 0.4 s, then off again, then under to the end: the end counts."""
    t = np.arange(40) / 30.0
    errors = np.full((40, len(MARKERS)), 0.05)
    errors[12] = 0.4  # frames 0-11 (0.37 s) good, then one bad frame
    times = initialisation_times(errors, np.zeros(40, dtype=int), t)
    assert times == {0: pytest.approx(13 / 30.0, abs=1e-4)}  # from frame 13 on to the end (0.87 s)
