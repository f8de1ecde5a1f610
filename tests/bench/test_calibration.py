"""The steps of ``optrack bench calibration`` on a small synthetic session (the figures come
from the command, on 10 sensors x 300 views)."""

from __future__ import annotations

from optrack.bench.calibration import _global_solve_figures, _live_feedback_figures
from optrack.calibration.synthetic import synthetic_session


def test_the_global_and_the_live_solve_find_the_true_poses():
    session = synthetic_session(3, 30, floor_views=2, seed=0)
    solve = _global_solve_figures(session, repeat=2)
    assert solve["ba_seconds_10x300"] > 0 and solve["ba_cpu_seconds_10x300"] > 0
    assert solve["max_position_error_m"] < 0.01 and solve["max_rotation_error_deg"] < 0.2
    live = _live_feedback_figures(session)
    assert live["feedback_hz"] > 0
    assert live["feedback_ms_median"] <= live["feedback_ms_p95"] <= live["feedback_ms_max"]
    assert live["floor_views"] == 2 and live["reprojection_rms_px"] < 1.0
