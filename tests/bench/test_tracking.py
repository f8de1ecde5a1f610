"""The pieces of ``optrack bench tracking`` (figures come from the command, not from here)."""

from __future__ import annotations

from optrack.bench.tracking import (
    OURS_GRID,
    BenchStream,
    _compare,
    _oracle_setting,
    ours_grid,
    run_norfair,
    run_ours,
    single_setting,
    speed_20x10,
)
from optrack.evaluation.clear_mot import MotScore
from optrack.sim.detections import crowd_scene, render
from optrack.tracking.params import TRACKING_PARAMS


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


def _score(mota: float, idsw: int) -> MotScore:
    return MotScore(mota, 0.05, 0, 0, idsw, 1.0, 1.0, 10, 10, 10)


def test_the_oracle_is_the_best_setting_of_each_stream() -> None:
    runs = [(_score(0.9, 3), 1.0), (_score(0.95, 5), 1.0), (_score(0.95, 2), 1.0)]
    assert _oracle_setting(runs) == 2


def test_the_single_setting_is_the_best_mean_mota_over_all_streams() -> None:
    # setting 0 wins stream a, setting 1 wins stream b, setting 2 wins neither but is
    # the best on average: one setting for every stream picks 2
    a = [(_score(0.99, 0), 1.0), (_score(0.50, 0), 1.0), (_score(0.95, 0), 1.0)]
    b = [(_score(0.40, 0), 1.0), (_score(0.98, 0), 1.0), (_score(0.90, 0), 1.0)]
    assert [_oracle_setting(a), _oracle_setting(b)] == [0, 1]
    assert single_setting([a, b]) == 2
    # equal means: fewer switches in all
    c = [(_score(0.9, 4), 1.0), (_score(0.9, 1), 1.0)]
    assert single_setting([c, c]) == 1


def test_norfair_is_reported_with_its_oracle_and_its_single_setting() -> None:
    streams = [_stream(3.0), _stream(3.0)]
    streams[1].name = "tiny-2"
    out = _compare(streams, min_confidence=-1.5, norfair_ok=True)
    single = out.pop("_single")
    assert set(single["settings"]) == {"distance", "memory_s", "delay_s", "min_confidence"}
    for entry in out.values():
        oracle, one = entry["norfair"], entry["norfair_single"]
        assert one["settings"] == single["settings"]
        # the oracle is chosen on the stream itself: never worse than the single setting
        assert oracle["mota"] >= one["mota"]
        assert {"mota", "idsw", "ms_per_update"} <= set(oracle) & set(one)
        ours = entry["ours"]
        assert entry["better_than_norfair"] == (
            ours["mota"] > oracle["mota"] and ours["idsw"] < oracle["idsw"]
        )
        assert entry["better_than_norfair_single"] == (
            ours["mota"] > one["mota"] and ours["idsw"] < one["idsw"]
        )
        # ours tuned on the stream: the best of our grid, never worse than the defaults
        tuned = entry["ours_tuned"]
        assert tuned["settings"] in ours_grid()
        assert (tuned["mota"], -tuned["idsw"]) >= (ours["mota"], -ours["idsw"])
        assert entry["better_tuned_than_norfair"] == (
            tuned["mota"] > oracle["mota"] and tuned["idsw"] < oracle["idsw"]
        )


def test_our_grid_starts_at_the_defaults_and_holds_valid_settings() -> None:
    """Tuned per stream, our tracker's first grid point is what it runs untuned; every
    point is a setting the parameter schema accepts."""
    settings = ours_grid()
    assert len(settings) == 4 and len({tuple(s.items()) for s in settings}) == 4
    defaults = TRACKING_PARAMS.create()
    assert all(getattr(defaults, name) == values[0] for name, values in OURS_GRID.items())
    for setting in settings:
        TRACKING_PARAMS.create(setting)


def test_the_tuned_entry_is_the_best_of_our_grid_on_the_stream() -> None:
    """The tuned entry reports the grid point that scores best on the stream (each point
    scored independently here)."""
    stream = _stream(6.0)
    scores = [run_ours(stream, s)[0] for s in ours_grid()]
    out = _compare([stream], min_confidence=-1.5, norfair_ok=True)
    best = max(scores, key=lambda m: (m.mota, -m.idsw))
    assert out["tiny"]["ours_tuned"]["mota"] == round(best.mota, 4)
    assert out["tiny"]["ours_tuned"]["idsw"] == best.idsw
