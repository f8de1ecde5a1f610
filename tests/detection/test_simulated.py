"""The detector on simulated Kinect v2 recordings, scored per frame against ground truth.

Short recordings (one second, three sensors, seed 2) keep this quick; the
bench (``optrack bench detection``) scores longer ones with another seed.
"""

from __future__ import annotations

import json

import msgspec
import pytest

from optrack.cli import main
from optrack.detection.evaluate import evaluate_recording

SEED = 2
SECONDS = 1.0


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    from optrack.sim.recorder import write_recording
    from optrack.sim.scenario import load_scenario
    from optrack.sim.world import Simulation

    mixed = load_scenario("mixed")
    dark = msgspec.structs.replace(
        mixed,
        venue=msgspec.structs.replace(
            mixed.venue, lighting=msgspec.structs.replace(mixed.venue.lighting, level=0.02)
        ),
    )
    root = tmp_path_factory.mktemp("sim")
    paths = {}
    for name, scenario in (("crowd", "crowd"), ("occlusions", "occlusions"), ("dark", dark)):
        sim = Simulation(scenario, seed=SEED, sensors=3, sensor_model="kinect2", seconds=SECONDS)
        write_recording(sim, root / name)
        paths[name] = root / name
    return paths


@pytest.mark.parametrize("scenario", ["crowd", "occlusions"])
def test_lit_scenes_find_nine_in_ten_half_visible_people_and_little_else(recordings, scenario):
    score = evaluate_recording(recordings[scenario])
    assert score.frames == 90 and score.required > 50
    assert score.recall >= 0.9, score.as_dict()
    assert score.precision >= 0.95, score.as_dict()
    assert set(score.sources) == {"color"}


def test_dark_scene_finds_nine_in_ten_from_depth_alone(recordings):
    # the trained depth classifier (OpenCV's people detector on the silhouette: 0.90)
    score = evaluate_recording(recordings["dark"])
    assert set(score.sources) == {"depth"}  # the luminance gate turned colour HOG off
    assert score.recall >= 0.9, score.as_dict()
    assert score.precision >= 0.98, score.as_dict()


def test_detect_command_reads_a_recording_in_the_world_frame(recordings, capsys):
    assert main(["detect", str(recordings["crowd"]), "--frames", "6", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["frames"] == 6 and result["frame_id"] == "world"
    assert set(result["grounds"]) == set(result["sensors"])
    assert result["detections"] and all("sensor" in d and "t" in d for d in result["detections"])
    for plane in result["grounds"].values():  # the simulated sensors hang 2.4 m up
        assert plane[3] == pytest.approx(2.4, abs=0.05)


def test_detect_command_reads_a_live_simulated_sensor(capsys):
    assert main(["detect", "sim://crowd/0", "--frames", "2", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["frames"] == 2 and result["frame_id"] == "world" and result["detections"]


def test_unknown_sensor_of_a_recording_is_refused(recordings, capsys):
    argv = ["detect", str(recordings["crowd"]), "--sensor", "nope"]
    assert main(argv) == 1
    err = capsys.readouterr().err.strip()
    assert "has no sensor 'nope'" in err and err.count("\n") == 0
