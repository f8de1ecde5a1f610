"""The steps of ``optrack bench e2e`` (the whole bench runs a site for half a minute: that is
for the command): the UDP receiver and the figures made of datagrams and node statuses."""

from __future__ import annotations

import json

import pytest

from optrack.bench.e2e import (
    _cpu_by_name,
    _datagram_figures,
    _node_figures,
    _Window,
)
from optrack.net.messages import StatusMessage


def _datagram(sec: int, nsec: int, tracks: int, frame_id: str = "world") -> bytes:
    header = {"stamp": {"sec": sec, "nsec": nsec}, "frame_id": frame_id}
    return json.dumps({"header": header, "tracks": [{}] * tracks}).encode()


def _window(**changes) -> _Window:
    values = {
        "t0_wall": 100.0,
        "t1_wall": 110.0,
        "elapsed": 10.0,
        "statuses_before": {},
        "statuses": {},
        "cpu": {},
        "roles": {},
        "restarts": 0,
    }
    values.update(changes)
    return _Window(**values)


def test_latency_counts_each_new_stamp_once_and_repeats_and_heartbeats_apart():
    arrivals = [
        (99.0, _datagram(98, 0, 9)),  # before the window: not counted
        (101.0, _datagram(100, 900_000_000, 2)),  # 100 ms old
        (101.5, _datagram(100, 900_000_000, 2)),  # the same stamp again: a repeat
        (102.0, _datagram(101, 800_000_000, 3)),  # 200 ms old
        (103.0, _datagram(0, 0, 0, "heartbeat")),
        (111.0, _datagram(110, 0, 9)),  # after the window
    ]
    figures = _datagram_figures(arrivals, _window())
    assert figures["latency_ms_median"] == pytest.approx(150.0)
    assert figures["latency_ms_max"] == pytest.approx(200.0)
    assert figures["output_hz"] == pytest.approx(0.3)  # three tracks datagrams in 10 s
    assert figures["repeat_hz"] == pytest.approx(0.1)
    assert figures["heartbeat_hz"] == pytest.approx(0.1)
    assert figures["datagrams"] == 4 and figures["max_tracks"] == 3


def test_no_datagram_gives_no_latency():
    figures = _datagram_figures([], _window())
    assert figures["latency_ms_median"] is None and figures["tracks_p95"] is None
    assert figures["datagrams"] == 0


def test_node_figures_are_growth_over_the_window_and_cpu_by_role():
    def status(node: str, role: str, **fields) -> StatusMessage:
        return StatusMessage(node=node, role=role, state="running", stamp=0.0, **fields)

    before = {
        "cam0": status("cam0", "detector", dropped=1, values={"frames": 100}),
        "tracker": status("tracker", "tracker", values={"batches": 50, "published": 40}),
    }
    after = {
        "cam0": status(
            "cam0",
            "detector",
            fps=29.0,
            latency_ms=40.0,
            dropped=4,
            values={"frames": 400, "wait_ms": 5.0, "processing_ms": 30.0},
        ),
        "tracker": status(
            "tracker", "tracker", latency_ms=60.0, values={"batches": 350, "published": 340}
        ),
    }
    window = _window(
        statuses_before=before,
        statuses=after,
        cpu={"launcher": 1.0, "cam0": 5.0, "tracker": 2.0},
        roles={"cam0": "detector", "tracker": "tracker"},
    )
    figures = _node_figures(window, ["cam0"])
    assert figures["detector_hz"] == [29.0] and figures["detector_latency_ms"] == [40.0]
    assert figures["detector_frames_hz"] == [30.0]
    assert figures["tracker_batches_hz"] == 30.0 and figures["tracker_sent_hz"] == 30.0
    assert figures["tracker_repeats_hz"] is None  # the tracker did not report repeats
    assert figures["detector_wait_ms"] == [5.0] and figures["detector_processing_ms"] == [30.0]
    assert figures["tracker_latency_ms"] == 60.0 and figures["outputs_latency_ms"] is None
    assert figures["dropped_frames"] == 3
    assert figures["cpu_percent_by_role"] == {"launcher": 10.0, "detector": 50.0, "tracker": 20.0}
    assert figures["cpu_percent"] == pytest.approx(80.0)


def test_cpu_is_by_node_with_every_other_process_of_the_launcher_as_launcher():
    before = {10: 1.0, 11: 0.5, 20: 3.0, 30: 2.0}  # launcher, its fork server, a detector, tracker
    after = {10: 1.5, 11: 0.75, 20: 7.0}  # the tracker ended (restarted): not counted
    names = {20: "cam0", 30: "tracker"}
    assert _cpu_by_name(before, after, names) == {"launcher": 0.75, "cam0": 4.0, "tracker": 0.0}
