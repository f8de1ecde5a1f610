"""Open Sound Control output (python-osc), one bundle per tracker frame.

Each bundle (time tag "immediately") holds::

    /optrack/frame  seq:int  sec:int  nsec:int  count:int
    /optrack/track  id:int  x:float  y:float  height:float     (one per track)

and each heartbeat is a bundle with ``/optrack/alive max_ID:int id:int...``.
Skeletons (while the skeleton stage runs) go in bundles of their own::

    /optrack/skeletons  seq:int  sec:int  nsec:int  count:int
    /optrack/skeleton/<id>/<joint>  x:float  y:float  z:float   (every joint of every skeleton)

with optrack's joint names (``left_wrist``); a frame whose bundle would pass
``max_bytes`` is sent as several, each starting with ``/optrack/skeletons``.
Positions are metres in the world frame, as in the JSON output.
"""

from __future__ import annotations

from collections.abc import Sequence

from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message_builder import OscMessageBuilder

from optrack.outputs.openptrack_json import stamp
from optrack.types import Skeleton, SkeletonBatch, TrackBatch

__all__ = ["alive_bundle", "frame_bundle", "skeleton_bundles"]

ADDRESS_FRAME = "/optrack/frame"
ADDRESS_TRACK = "/optrack/track"
ADDRESS_ALIVE = "/optrack/alive"
ADDRESS_SKELETONS = "/optrack/skeletons"
ADDRESS_SKELETON = "/optrack/skeleton"


def _message(address: str, *args: tuple[object, str]) -> object:
    builder = OscMessageBuilder(address=address)
    for value, kind in args:
        builder.add_arg(value, kind)
    return builder.build()


def frame_bundle(seq: int, batch: TrackBatch) -> bytes:
    """The OSC bundle of one frame of tracks, as one datagram."""
    t = stamp(batch.stamp)
    bundle = OscBundleBuilder(IMMEDIATELY)
    bundle.add_content(
        _message(
            ADDRESS_FRAME,
            (seq, "i"),
            (t["sec"], "i"),
            (t["nsec"], "i"),
            (len(batch.tracks), "i"),
        )
    )
    for track in batch.tracks:
        bundle.add_content(
            _message(
                ADDRESS_TRACK,
                (int(track.id), "i"),
                (float(track.x), "f"),
                (float(track.y), "f"),
                (float(track.height), "f"),
            )
        )
    return bundle.build().dgram


def alive_bundle(alive_ids: Sequence[int], max_id: int) -> bytes:
    """The heartbeat as an OSC bundle."""
    bundle = OscBundleBuilder(IMMEDIATELY)
    bundle.add_content(
        _message(ADDRESS_ALIVE, (int(max_id), "i"), *((int(i), "i") for i in alive_ids))
    )
    return bundle.build().dgram


def _skeletons_bundle(seq: int, t: dict[str, int], skeletons: list[Skeleton]) -> bytes:
    bundle = OscBundleBuilder(IMMEDIATELY)
    bundle.add_content(
        _message(
            ADDRESS_SKELETONS, (seq, "i"), (t["sec"], "i"), (t["nsec"], "i"), (len(skeletons), "i")
        )
    )
    for skeleton in skeletons:
        for joint, (x, y, z, _) in skeleton.joints.items():
            bundle.add_content(
                _message(
                    f"{ADDRESS_SKELETON}/{int(skeleton.id)}/{joint}",
                    (float(x), "f"),
                    (float(y), "f"),
                    (float(z), "f"),
                )
            )
    return bundle.build().dgram


def skeleton_bundles(seq: int, batch: SkeletonBatch, max_bytes: int) -> list[bytes]:
    """The OSC bundles of one frame of skeletons: one, or several of whole skeletons when
    one would pass ``max_bytes``."""
    t = stamp(batch.stamp)
    pending = [list(batch.skeletons)]
    out: list[bytes] = []
    while pending:
        skeletons = pending.pop(0)
        dgram = _skeletons_bundle(seq, t, skeletons)
        if len(dgram) <= max_bytes or len(skeletons) <= 1:
            out.append(dgram)
        else:
            half = len(skeletons) // 2
            pending[:0] = [skeletons[:half], skeletons[half:]]
    return out
