"""``optrack bench detection``: the real-frame figures and the command's registration (the
whole bench also simulates and times minutes of frames: that is for the command)."""

from __future__ import annotations

from optrack.bench.cli import BENCHES, cmd_bench_detection
from optrack.bench.detection import real_frame_figures


def test_bench_real_frame_figures_meet_pcls_answers(shared_data):
    # The whole bench also simulates and times minutes of frames: that is for
    # `optrack bench detection`, not for the test suite.
    result = real_frame_figures(shared_data)
    assert result["five_people_ms"] > 0 and result["five_people_ms_cpu"] > 0
    assert result["five_people_count"] == 5 and result["five_people_count_pcl_ground"] == 5
    assert result["five_people_max_error_m"] < 0.2
    assert result["ground_angle_deg"] < 3 and result["ground_offset_m"] < 0.05
    assert result["office1_count"] == 0


def test_bench_detection_is_registered():
    assert BENCHES["detection"] is cmd_bench_detection
