"""Pieces of ``optrack bench site`` that need no namespaces (the whole bench runs in
tests/runtime/test_netns_site.py, as root)."""

from __future__ import annotations

from optrack.bench.site import _ids_kept, silent, tracking


def test_ids_kept_matches_people_by_position_within_a_walk():
    before = [[3, 0.0, 0.0], [5, 2.0, 0.0]]
    # person 3 kept its id; person 5 moved 0.6 m in 0.2 s... and got id 1
    assert _ids_kept(before, [[3, 0.1, 0.0], [1, 2.6, 0.0]], 0.2) == 1
    # the same ids on other people far away are not kept ids
    assert _ids_kept(before, [[5, 0.0, 0.1], [3, 2.0, 0.1]], 0.2) == 0
    assert _ids_kept(before, [], 1.0) == 0
    assert _ids_kept([], [[1, 0.0, 0.0]], 1.0) == 0


def test_events_read_by_the_steps():
    assert tracking({"ok": True, "ids": [1]})
    assert not tracking({"ok": True, "ids": []})  # a frame with nobody
    assert not tracking({"ok": True, "ids": None})  # a heartbeat
    assert not tracking({"ok": False, "ids": None})
    assert silent({"values": {"silent_sensors": "kinect2_0,kinect2_2"}}, "kinect2_2")
    assert not silent({"values": {"silent_sensors": "kinect2_00"}}, "kinect2_0")
    assert not silent({"values": {}}, "kinect2_0")
