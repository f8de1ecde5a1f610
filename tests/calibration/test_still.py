"""The still-board rule (optrack.calibration.still) that the offline session and the live
calibration share: sensors whose still intervals share a moment saw one board pose."""

import numpy as np
import pytest

from optrack.calibration.still import StillBoards, corner_motion_px

CORNERS = np.array([[100.0, 100.0], [140.0, 100.0], [100.0, 140.0], [140.0, 140.0]])


def at(shift: float) -> np.ndarray:
    return CORNERS + shift


def test_sensors_searching_at_their_own_instants_share_the_board_held_still():
    """Live: a and b search three times a second at different instants; the board is held
    still from 1 s to 3 s, then carried away (the corners move 20 px per search)."""
    still = StillBoards(["a", "b"], max_motion_px=2.0, max_gap_s=3.0)
    boards = []
    for k in range(15):
        for sensor, offset in (("a", 0.0), ("b", 0.13)):
            t = k / 3 + offset
            held = 1.0 <= t <= 3.0
            still.add(sensor, t, at(0.0 if held else 20.0 * t), on_floor=False)
            boards += still.ready()
    boards += still.ready(final=True)
    shared = [b for b in boards if set(b.corners) == {"a", "b"}]
    assert len(shared) >= 4  # every third of a second or so of the hold, both sensors
    assert len(boards) - len(shared) <= 1  # a alone at the hold's end (b's next search moved)
    for b in boards:
        assert 1.0 <= b.start < b.end <= 3.0 + 0.13  # inside the hold
        assert not b.on_floor()
    ends = [b.end for b in boards]
    assert ends == sorted(ends)


def test_a_recording_read_in_bins_makes_one_still_board_per_bin_ready_at_once():
    """Offline: every sensor's frame of a bin is stamped with the bin's time."""
    still = StillBoards(["a", "b", "c"], max_motion_px=2.0)
    per_bin = []
    for k in range(4):
        t = 0.5 * k
        for sensor in ("a", "b", "c"):
            still.add(sensor, t, at(0.5), on_floor=sensor != "c")
        per_bin.append(still.ready())
    assert [len(b) for b in per_bin] == [0, 1, 1, 1]  # the first bin has no previous view
    assert [b[0].end for b in per_bin[1:]] == [0.5, 1.0, 1.5]
    assert all(set(b[0].corners) == {"a", "b", "c"} and b[0].on_floor() for b in per_bin[1:])
    assert not per_bin[1][0].on_floor(["c"])  # the majority of the sensors asked


def test_a_board_waits_for_a_silent_sensor_until_the_gap_has_passed():
    still = StillBoards(["a", "b"], max_motion_px=2.0, max_gap_s=1.0)
    still.add("a", 0.0, at(0.0))
    still.add("a", 0.3, at(0.5))
    assert still.ready() == []  # b may still search a frame from before 0.3
    still.add("a", 0.9, at(30.0))  # moved: no still board
    assert still.ready() == []
    still.add("a", 1.4, None)
    [board] = still.ready()  # more than max_gap_s after its end
    assert set(board.corners) == {"a"} and (board.start, board.end) == (0.0, 0.3)


def test_a_moving_board_or_a_long_gap_is_not_still_and_no_check_keeps_every_find():
    still = StillBoards(["a"], max_motion_px=2.0, max_gap_s=1.0)
    still.add("a", 0.0, at(0.0))
    still.add("a", 0.5, at(3.0))  # moved 3 px
    still.add("a", 2.0, at(3.0))  # 1.5 s after the last find
    assert still.ready(final=True) == []
    anything = StillBoards(["a"], max_motion_px=0.0, max_gap_s=1.0)
    anything.add("a", 0.0, at(0.0))
    anything.add("a", 0.5, at(30.0))
    assert [(b.start, b.end) for b in anything.ready(final=True)] == [(-1.0, 0.0), (0.0, 0.5)]


def test_corner_motion_is_the_rms_distance():
    assert corner_motion_px(at(3.0), at(0.0)) == pytest.approx(np.hypot(3.0, 3.0))
