"""The pieces of ``optrack bench tracking`` (figures come from the command, not from here)."""

from __future__ import annotations

from optrack.evaluation.synthetic import crowd_scene, render
from optrack.tracking.bench import BenchStream, run_norfair, run_ours, speed_20x10


def _stream(seconds: float = 8.0) -> BenchStream:
    scene = crowd_scene(people=4, sensors=2, seconds=seconds, seed=5)
    batches, truth = render(scene, seed=5)
    return BenchStream(
        "tiny", "synthetic", 2, batches, truth.times, truth.ids, truth.xy, truth.visible
    )


def test_speed_is_measured_with_20_people_and_10_sensors() -> None:
    result = speed_20x10(seconds=0.5)
    assert result["updates_20x10"] == 10 * 15  # 10 sensors at 30 Hz for 0.5 s
    assert result["detections_per_update_20x10"] > 1
    assert 0 < result["cpu_ms_per_update_20x10"] and 0 < result["ms_per_update_20x10"]


def test_our_tracker_is_scored_on_a_stream() -> None:
    score, ms = run_ours(_stream())
    assert score.frames == 241 and score.mota > 0.8 and ms > 0


def test_norfair_is_scored_on_the_same_stream() -> None:
    stream = _stream()
    score, ms = run_norfair(stream, distance=0.7, memory_s=1.0, delay_s=0.0, min_confidence=-1.5)
    assert score.frames == 241 and score.objects == run_ours(stream)[0].objects
    assert score.matches > 0 and ms > 0
