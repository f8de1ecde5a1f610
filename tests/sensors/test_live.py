"""Frame times from device clocks, and the choice of a video mode."""

from __future__ import annotations

import numpy as np
import pytest

from optrack.sensors.live import DeviceClock, Mode, nearest_mode


def test_anchored_times_follow_the_device_clock_from_the_host_time_of_the_first_frame():
    clock = DeviceClock("anchored", period=1 / 30)
    t0 = clock.stamp(5.000, now=1000.050)
    t1 = clock.stamp(5.033, now=1000.095)  # arrived late: the device spacing is kept
    assert t0 == pytest.approx(1000.050)
    assert t1 - t0 == pytest.approx(0.033)


def test_anchored_offset_slews_down_when_frames_arrive_sooner_than_it_allows():
    clock = DeviceClock("anchored", period=0.1)
    clock.stamp(1.0, now=100.080)  # the first frame had 80 ms of latency
    stamps = [clock.stamp(1.0 + 0.1 * k, now=100.010 + 0.1 * k) for k in range(1, 60)]
    steps = np.diff(stamps)
    assert np.all(steps >= 0.1 - 0.002 - 1e-9) and np.all(steps <= 0.1 + 1e-9)  # spacing kept
    assert stamps[-1] == pytest.approx(100.010 + 5.9)  # converged to the 10 ms latency


def test_anchored_times_are_anchored_again_when_they_fall_far_behind_the_host():
    clock = DeviceClock("anchored", period=1 / 30, max_skew=0.5)
    clock.stamp(0.0, now=10.0)
    assert clock.stamp(1.0, now=12.0) == pytest.approx(12.0)
    assert clock.anchors == 2


def test_device_clock_reset_never_sends_time_backwards():
    clock = DeviceClock("device", period=0.1)
    times = [clock.stamp(t) for t in (1.0, 1.1, 1.2)]
    clock.restart()  # device reopened: its clock starts again
    times += [clock.stamp(t) for t in (0.0, 0.1)]
    assert times == pytest.approx([1.0, 1.1, 1.2, 1.3, 1.4])


def test_anchored_clock_after_reconnect_continues_forward():
    clock = DeviceClock("anchored", period=1 / 30)
    a = clock.stamp(100.0, now=50.0)
    clock.restart()
    b = clock.stamp(0.033, now=49.99)  # host clock stepped back a little meanwhile
    assert b > a


def test_host_mode_uses_arrival_time_but_stays_monotonic():
    clock = DeviceClock("host")
    assert clock.stamp(0.0, now=5.0) == 5.0
    assert clock.stamp(0.0, now=4.9) > 5.0


def test_unknown_timestamp_mode_is_refused():
    with pytest.raises(ValueError, match="anchored"):
        DeviceClock("ptp")


MODES = [
    Mode(320, 240, 30, "depth_mm"),
    Mode(640, 480, 30, "depth_mm"),
    Mode(640, 480, 60, "depth_mm"),
    Mode(640, 480, 30, "shift"),
    Mode(1280, 1024, 30, "depth_mm"),
]


def test_exact_mode_wins():
    assert nearest_mode(MODES, 640, 480, 60, ["depth_mm"]) == Mode(640, 480, 60, "depth_mm")


def test_nearest_size_then_rate_when_the_wanted_mode_is_missing():
    assert nearest_mode(MODES, 640, 480, 25, ["depth_mm"]) == Mode(640, 480, 30, "depth_mm")
    assert nearest_mode(MODES, 352, 288, 30, ["depth_mm"]) == Mode(320, 240, 30, "depth_mm")


def test_formats_outside_the_list_are_never_chosen():
    assert nearest_mode(MODES, 640, 480, 30, ["shift"]) == Mode(640, 480, 30, "shift")
    assert nearest_mode(MODES, 640, 480, 30, ["gray16"]) is None


def test_format_order_breaks_ties():
    modes = [Mode(640, 480, 30, "yuv"), Mode(640, 480, 30, "rgb")]
    assert nearest_mode(modes, 640, 480, 30, ["rgb", "yuv"]).format == "rgb"
