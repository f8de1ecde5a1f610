"""``optrack bench skeleton``: its keys on a few frames of each setting (the figures
themselves take minutes: that is for the command), its cache and its registration."""

from __future__ import annotations

import math

from optrack.bench.cli import BENCHES, cmd_bench_skeleton
from optrack.bench.skeleton import all_clips, skeleton_bench
from optrack.cli import main

KEYS = {
    "fps_1person_3sensors",
    "fps_4people_3sensors",
    "ms_per_frame_p50",
    "ms_per_frame_p95",
    "particles",
    "points_per_person",
    "accuracy",
    "reference_ms",
}
FIGURES = {"mean_error_m", "markers", "pct_under_0_10", "pct_under_0_15", "pct_under_0_20"}
FIGURES |= {"lost_pct", "frames"}


def test_bench_skeleton_keys_on_a_few_frames(shared_data, tmp_path, monkeypatch):
    monkeypatch.setenv("OPTRACK_CACHE", str(tmp_path))
    clip = "cmu_16_27_walk_turn_left.bvh"
    result = skeleton_bench(seconds=0.2, clips=(clip,), speed_seconds=0.1, seeds=2, jobs=2)
    assert KEYS <= set(result)
    assert result["particles"] == 2000 and result["points_per_person"] == 500
    # Auto threads by default: what it gave is a count of this machine's cores.
    assert result["threads"] == 0 and 1 <= result["threads_used"] <= result["cpu_count"]
    for key in (
        "fps_1person_3sensors",
        "fps_4people_3sensors",
        "ms_per_frame_p50",
        "cpu_ms_per_frame_p50",
    ):
        assert math.isfinite(result[key]) and result[key] > 0
    assert result["ms_per_frame_p95"] >= result["ms_per_frame_p50"]
    # The machine's speed beside them: a fixed workload's CPU time before and after.
    before, after = result["reference_ms_before_after"]
    assert 0 < before and 0 < after and result["reference_ms"] == round((before + after) / 2, 3)
    assert set(result["accuracy"]) == {"3_sensors", "2_sensors", "1_sensor"}
    for setting in result["accuracy"].values():
        assert FIGURES <= set(setting)
        assert setting["frames"] == 12  # 0.2 s at 30 Hz, two seeds
        assert setting["runs"] == 2 and 0 <= setting["runs_over_0_10"] <= 2
        assert set(setting["clips"]) == {"cmu_16_27_walk_turn_left"}
        walk = setting["clips"]["cmu_16_27_walk_turn_left"]
        assert walk["frames"] == 12 and len(walk["mean_error_m_by_seed"]) == 2
        init = setting["initialisation"]
        assert set(init["init_s"]) == {
            "cmu_16_27_walk_turn_left/0/0",
            "cmu_16_27_walk_turn_left/1/0",
        }
        assert set(init) == {"init_s", "init_s_median", "init_s_max", "init_within_1s"}
    # The two seeds are two runs: the filter's draws differ, so do the estimates.
    three = result["accuracy"]["3_sensors"]["clips"]["cmu_16_27_walk_turn_left"]
    assert three["mean_error_m_by_seed"][0] != three["mean_error_m_by_seed"][1]
    assert result["seeds"] == 2 and result["clips"] == ["cmu_16_27_walk_turn_left"]
    crowd = result["initialisation_4people_3sensors"]
    assert len(crowd["init_s"]) == 4 and 0.0 <= crowd["init_within_1s"] <= 1.0
    cached = sorted(p.name for p in (tmp_path / "bench").iterdir())
    assert len(cached) == 2 and all(p.startswith("skeleton-") for p in cached)


def test_bench_skeleton_scores_every_clip_by_default(shared_data):
    assert all_clips() == tuple(sorted(p.name for p in (shared_data / "mocap").glob("*.bvh")))
    assert len(all_clips()) >= 6 and "cmu_131_02_alt_naming.bvh" in all_clips()


def test_bench_skeleton_refuses_an_unknown_clip_bad_counts_and_a_bad_config(
    shared_data, capsys, tmp_path
):
    code = main(["bench", "skeleton", "--clips", "cmu_16_27_walk_turn_left,not_a_clip"])
    err = capsys.readouterr().err
    assert code == 1 and "not_a_clip.bvh" in err and "cmu_16_27_walk_turn_left.bvh" in err
    assert main(["bench", "skeleton", "--seeds", "0"]) == 1
    assert "--seeds must be at least 1" in capsys.readouterr().err
    assert main(["bench", "skeleton", "--seconds", "-1"]) == 1
    assert "--seconds must be positive" in capsys.readouterr().err
    missing = tmp_path / "none.yaml"
    assert main(["bench", "skeleton", "--config", str(missing)]) == 1
    assert f"config file {missing} does not exist" in capsys.readouterr().err
    wrong = tmp_path / "wrong.yaml"
    wrong.write_text("skeleton:\n  limb_research_margin: 9\n")
    assert main(["bench", "skeleton", "--config", str(wrong)]) == 1
    assert "limb_research_margin must be between 0 and 2" in capsys.readouterr().err


def test_bench_skeleton_skips_without_its_clips():
    result = skeleton_bench(clips=("not_a_clip.bvh",))
    assert set(result) == {"skipped"} and "not_a_clip.bvh" in result["skipped"]


def test_bench_skeleton_is_registered():
    assert BENCHES["skeleton"] is cmd_bench_skeleton


def test_the_reference_workload_is_timed_in_cpu_milliseconds():
    """A fixed workload: one call of it costs milliseconds of CPU on any computer this
    runs on (the torso's likelihood of 2000 poses), never nothing."""
    from optrack.bench.skeleton import reference_ms

    assert 0.05 < reference_ms(repeats=3, calls=2) < 1000.0
