"""OpenPTrack's JSON over UDP, byte for byte what its receivers parse.

Two documents, one per datagram, UTF-8, with no trailing NUL byte (OpenPTrack
appended one, which breaks Max/MSP's and Python's parsers)::

    {"header":{"seq":12,"stamp":{"sec":1700000000,"nsec":250000000},"frame_id":"world"},
     "tracks":[{"id":3,"x":1.25,"y":-0.5,"height":1.72,"age":4.2,"confidence":0.9}]}

    {"header":{"seq":5,"stamp":{...},"frame_id":"heartbeat"},"alive_IDs":[3,7],"max_ID":7}

``x, y`` are metres on the floor in the world frame, ``height`` metres,
``age`` seconds since the track started. Each stream (tracks, heartbeat,
skeletons) has its own ``seq``.

Skeletons (while the skeleton stage runs) follow OpenPTrack v2's pose message,
one document for every skeleton of a frame::

    {"header":{"seq":4,"stamp":{...},"frame_id":"world"},
     "pose_tracks":[{"id":3,"height":1.72,"state":"tracking","rate_hz":14.8,
                     "joints":{"HEAD":{"x":1.2,"y":-0.5,"z":1.63,"confidence":0.9}, ...}}]}

Joint names are v2's (:data:`POSE_JOINT_NAMES`: ours upper-cased, ``spine`` as
v2's ``CHEST``, and ``pelvis``, which v2 has not, as ``PELVIS``); a joint without a
position is left out, as v2 does. ``state`` and ``rate_hz`` are optrack's.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterable, Sequence
from typing import Any

from optrack.types import Skeleton, SkeletonBatch, Track, TrackBatch

__all__ = [
    "POSE_JOINT_NAMES",
    "encode",
    "heartbeat_document",
    "pose_name",
    "skeleton_datagrams",
    "skeletons_document",
    "stamp",
    "track_datagrams",
    "tracks_document",
]

#: optrack's joint names (optrack/skeleton/joints.py) as OpenPTrack v2's pose message
#: names them (its ``SkeletonBase::JOINT_NAMES``); the pelvis, which v2 has not, is PELVIS.
POSE_JOINT_NAMES = {
    "pelvis": "PELVIS",
    "spine": "CHEST",
    "neck": "NECK",
    "head": "HEAD",
    "left_shoulder": "LEFT_SHOULDER",
    "left_elbow": "LEFT_ELBOW",
    "left_wrist": "LEFT_WRIST",
    "right_shoulder": "RIGHT_SHOULDER",
    "right_elbow": "RIGHT_ELBOW",
    "right_wrist": "RIGHT_WRIST",
    "left_hip": "LEFT_HIP",
    "left_knee": "LEFT_KNEE",
    "left_ankle": "LEFT_ANKLE",
    "right_hip": "RIGHT_HIP",
    "right_knee": "RIGHT_KNEE",
    "right_ankle": "RIGHT_ANKLE",
}


def pose_name(joint: str) -> str:
    """A joint's name in the pose message (an unknown one upper-cased)."""
    return POSE_JOINT_NAMES.get(joint, joint.upper())


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


def skeleton_entry(skeleton: Skeleton) -> dict[str, Any]:
    return {
        "id": int(skeleton.id),
        "height": float(skeleton.height),
        "state": skeleton.state,
        "rate_hz": float(skeleton.rate_hz),
        "joints": {
            pose_name(name): {
                "x": float(x),
                "y": float(y),
                "z": float(z),
                "confidence": float(confidence),
            }
            for name, (x, y, z, confidence) in skeleton.joints.items()
        },
    }


def skeletons_document(
    seq: int, t: float, skeletons: Iterable[Skeleton], frame_id: str = "world"
) -> dict[str, Any]:
    return {
        "header": header(seq, t, frame_id),
        "pose_tracks": [skeleton_entry(s) for s in skeletons],
    }


def _split(items: list[Any], document: Callable[[list[Any]], dict], max_bytes: int) -> list[bytes]:
    """The document of ``items``, split in halves (each a complete document) only when
    it would not fit in ``max_bytes``."""
    whole = encode(document(items))
    if len(whole) <= max_bytes or len(items) <= 1:
        return [whole]
    half = len(items) // 2
    return _split(items[:half], document, max_bytes) + _split(items[half:], document, max_bytes)


def track_datagrams(seq: int, batch: TrackBatch, max_bytes: int) -> list[bytes]:
    """The tracks document of a batch, split into several documents of the same
    ``seq`` only when one would not fit in ``max_bytes`` (hundreds of people)."""
    return _split(
        list(batch.tracks),
        lambda tracks: tracks_document(seq, batch.stamp, tracks, batch.frame_id),
        max_bytes,
    )


def skeleton_datagrams(seq: int, batch: SkeletonBatch, max_bytes: int) -> list[bytes]:
    """The pose document of a skeleton batch, split like :func:`track_datagrams`."""
    return _split(
        list(batch.skeletons),
        lambda skeletons: skeletons_document(seq, batch.stamp, skeletons, batch.frame_id),
        max_bytes,
    )
