"""``optrack bench sim``: the command runs and reports its figure (speed is measured by
running the command, not asserted here)."""

from __future__ import annotations

from optrack.bench.sim import measure_kinect2_fps


def test_bench_renders_kinect2_depth_and_infrared_of_seven_people():
    result = measure_kinect2_fps(runs=2, frames=3, warmup=1, people=7, scenario="crowd")
    assert result["kinect2_fps"] > 0
    assert len(result["runs_fps"]) == 2
    assert (result["width"], result["height"]) == (512, 424)
    assert result["people"] == 7 and result["people_in_view_mean"] >= 3
    assert result["streams"] == ["depth", "infrared"]
