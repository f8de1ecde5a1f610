"""OpenPTrack's JSON over UDP, byte for byte what its receivers parse.

Two documents, one per datagram, UTF-8, with no trailing NUL byte (OpenPTrack
appended one, which breaks Max/MSP's and Python's parsers)::

    {"header":{"seq":12,"stamp":{"sec":1700000000,"nsec":250000000},"frame_id":"world"},
     "tracks":[{"id":3,"x":1.25,"y":-0.5,"height":1.72,"age":4.2,"confidence":0.9}]}

    {"header":{"seq":5,"stamp":{...},"frame_id":"heartbeat"},"alive_IDs":[3,7],"max_ID":7}

``x, y`` are metres on the floor in the world frame, ``height`` metres,
``age`` seconds since the track started. Each stream (tracks, heartbeat) has
its own ``seq``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Sequence
from typing import Any

from optrack.types import Track, TrackBatch

__all__ = ["encode", "heartbeat_document", "stamp", "track_datagrams", "tracks_document"]


def stamp(t: float) -> dict[str, int]:
    """Seconds as ROS's ``{"sec", "nsec"}`` (nsec in 0..999999999)."""
    sec = math.floor(t)
    nsec = round((t - sec) * 1e9)
    if nsec >= 1_000_000_000:
        sec, nsec = sec + 1, nsec - 1_000_000_000
    return {"sec": int(sec), "nsec": int(nsec)}


def header(seq: int, t: float, frame_id: str) -> dict[str, Any]:
    return {"seq": int(seq), "stamp": stamp(t), "frame_id": frame_id}


def track_entry(track: Track) -> dict[str, Any]:
    return {
        "id": int(track.id),
        "x": float(track.x),
        "y": float(track.y),
        "height": float(track.height),
        "age": float(track.age),
        "confidence": float(track.confidence),
    }


def tracks_document(
    seq: int, t: float, tracks: Iterable[Track], frame_id: str = "world"
) -> dict[str, Any]:
    return {"header": header(seq, t, frame_id), "tracks": [track_entry(k) for k in tracks]}


def heartbeat_document(seq: int, t: float, alive_ids: Sequence[int], max_id: int) -> dict[str, Any]:
    return {
        "header": header(seq, t, "heartbeat"),
        "alive_IDs": [int(i) for i in alive_ids],
        "max_ID": int(max_id),
    }


def encode(document: dict[str, Any]) -> bytes:
    """Compact UTF-8 JSON, no NUL terminator; NaN refused (JSON has none)."""
    return json.dumps(document, separators=(",", ":"), allow_nan=False).encode("utf-8")


def track_datagrams(seq: int, batch: TrackBatch, max_bytes: int) -> list[bytes]:
    """The tracks document of a batch, split into several documents of the same
    ``seq`` only when one would not fit in ``max_bytes`` (hundreds of people)."""
    tracks = list(batch.tracks)
    whole = encode(tracks_document(seq, batch.stamp, tracks, batch.frame_id))
    if len(whole) <= max_bytes or len(tracks) <= 1:
        return [whole]
    half = len(tracks) // 2
    first = TrackBatch(
        stamp=batch.stamp, seq=batch.seq, frame_id=batch.frame_id, tracks=tracks[:half]
    )
    second = TrackBatch(
        stamp=batch.stamp, seq=batch.seq, frame_id=batch.frame_id, tracks=tracks[half:]
    )
    return track_datagrams(seq, first, max_bytes) + track_datagrams(seq, second, max_bytes)
