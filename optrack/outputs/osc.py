"""Open Sound Control output (python-osc), one bundle per tracker frame.

Each bundle (time tag "immediately") holds::

    /optrack/frame  seq:int  sec:int  nsec:int  count:int
    /optrack/track  id:int  x:float  y:float  height:float     (one per track)

and each heartbeat is a bundle with ``/optrack/alive max_ID:int id:int...``.
Positions are metres in the world frame, as in the JSON output.
"""

from __future__ import annotations

from collections.abc import Sequence

from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message_builder import OscMessageBuilder

from optrack.outputs.openptrack_json import stamp
from optrack.types import TrackBatch

__all__ = ["alive_bundle", "frame_bundle"]

ADDRESS_FRAME = "/optrack/frame"
ADDRESS_TRACK = "/optrack/track"
ADDRESS_ALIVE = "/optrack/alive"


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
