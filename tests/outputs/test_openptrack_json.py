"""OpenPTrack's JSON documents, exactly: keys, stamps, one document per datagram, no NUL."""

from __future__ import annotations

import json
import math

import pytest

from optrack.outputs import openptrack_json as oj
from optrack.types import Track, TrackBatch


def test_tracks_document_has_openptracks_keys_in_order():
    batch = TrackBatch(
        stamp=1700000000.25,
        tracks=[Track(3, 1.25, -0.5, 1.72, age=4.2, confidence=0.9, vx=0.3)],
    )
    datagram = oj.track_datagrams(12, batch, 65000)[0]
    assert datagram == (
        b'{"header":{"seq":12,"stamp":{"sec":1700000000,"nsec":250000000},"frame_id":"world"},'
        b'"tracks":[{"id":3,"x":1.25,"y":-0.5,"height":1.72,"age":4.2,"confidence":0.9}]}'
    )
    assert not datagram.endswith(b"\x00")


def test_heartbeat_document_has_alive_ids_and_max_id():
    document = oj.heartbeat_document(5, 10.5, [3, 7], 7)
    assert oj.encode(document) == (
        b'{"header":{"seq":5,"stamp":{"sec":10,"nsec":500000000},"frame_id":"heartbeat"},'
        b'"alive_IDs":[3,7],"max_ID":7}'
    )


@pytest.mark.parametrize(
    ("t", "sec", "nsec"),
    [(0.0, 0, 0), (1.5, 1, 500_000_000), (2.9999999999, 3, 0), (-0.25, -1, 750_000_000)],
)
def test_stamp_is_whole_seconds_and_nanoseconds(t, sec, nsec):
    assert oj.stamp(t) == {"sec": sec, "nsec": nsec}


def test_empty_frame_is_still_a_document():
    (datagram,) = oj.track_datagrams(1, TrackBatch(stamp=3.0), 65000)
    assert json.loads(datagram)["tracks"] == []


def test_nan_is_refused_rather_than_sent_as_invalid_json():
    with pytest.raises(ValueError):
        oj.encode(oj.tracks_document(1, 1.0, [Track(1, math.nan, 0.0, 1.7)]))


def test_a_frame_too_big_for_one_datagram_becomes_several_complete_documents():
    batch = TrackBatch(stamp=5.0, tracks=[Track(i, i * 0.1, 0.0, 1.7) for i in range(200)])
    datagrams = oj.track_datagrams(9, batch, 2000)
    assert len(datagrams) > 1
    documents = [json.loads(d) for d in datagrams]
    assert all(len(d) <= 2000 for d in datagrams)
    assert all(doc["header"]["seq"] == 9 for doc in documents)
    assert [t["id"] for doc in documents for t in doc["tracks"]] == list(range(200))
