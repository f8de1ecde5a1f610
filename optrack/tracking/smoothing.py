"""Output smoothing (OpenPTrack's moving-average node) and the output messages.

The tracker emits tracks after every detection batch, at the uneven rate the
sensors give. :class:`OutputSmoother` averages each track's last ``window``
positions, republishes all tracks at a fixed ``rate``, leaves out tracks no
sensor has seen for ``drop_after`` seconds, and keeps the heartbeat: the IDs
alive and the largest ID ever given. It produces messages only; sending them
(UDP JSON, OSC, WebSocket) is the outputs' job. :func:`tracks_message` and
:func:`heartbeat_message` build OpenPTrack's JSON documents.
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from collections.abc import Iterable, Iterator

import msgspec

from optrack.params import Params
from optrack.tracking.params import SMOOTHING_PARAMS
from optrack.types import Track, TrackBatch, TrackStatus

__all__ = ["Heartbeat", "OutputSmoother", "heartbeat_message", "tracks_message"]


@dataclasses.dataclass(frozen=True)
class Heartbeat:
    stamp: float
    seq: int
    alive_ids: list[int]
    max_id: int


@dataclasses.dataclass
class _Smoothed:
    samples: deque[tuple[float, float, float]]
    last: Track
    seen: float


class OutputSmoother:
    """Moving average per track, fixed-rate republishing, heartbeat."""

    def __init__(self, params: Params | None = None) -> None:
        self.params = params if params is not None else SMOOTHING_PARAMS.create()
        self._tracks: dict[int, _Smoothed] = {}
        self.max_id = 0
        self.stamp = -math.inf
        self.seq = 0
        self.heartbeat_seq = 0

    def add(self, batch: TrackBatch) -> None:
        """Take the tracker's tracks at one moment."""
        window = self.params.window
        self.stamp = max(self.stamp, batch.stamp)
        for track in batch.tracks:
            entry = self._tracks.get(track.id)
            if entry is None or entry.samples.maxlen != window:
                samples = deque(entry.samples if entry else (), maxlen=window)
                entry = _Smoothed(samples, track, -math.inf if entry is None else entry.seen)
                self._tracks[track.id] = entry
            entry.samples.append((track.x, track.y, track.height))
            entry.last = track
            if track.status != TrackStatus.MISSING:
                entry.seen = max(entry.seen, batch.stamp)
            self.max_id = max(self.max_id, track.id)

    def _alive(self, now: float) -> list[int]:
        drop = self.params.drop_after
        for tid in [k for k, v in self._tracks.items() if now - v.seen > drop]:
            del self._tracks[tid]
        return sorted(self._tracks)

    def publish(self, now: float) -> TrackBatch:
        """Smoothed tracks seen within ``drop_after`` of ``now``."""
        self.seq += 1
        tracks = []
        for tid in self._alive(now):
            entry = self._tracks[tid]
            n = len(entry.samples)
            x = sum(s[0] for s in entry.samples) / n
            y = sum(s[1] for s in entry.samples) / n
            height = sum(s[2] for s in entry.samples) / n
            tracks.append(msgspec.structs.replace(entry.last, x=x, y=y, height=height))
        return TrackBatch(stamp=now, seq=self.seq, tracks=tracks)

    def heartbeat(self, now: float) -> Heartbeat:
        self.heartbeat_seq += 1
        return Heartbeat(now, self.heartbeat_seq, self._alive(now), self.max_id)

    def republish(self, batches: Iterable[TrackBatch]) -> Iterator[TrackBatch]:
        """Smoothed tracks at the fixed rate, in the stream's own time (batches in time order).

        A tick at time T shows every batch stamped up to T.
        """
        period = 1.0 / self.params.rate
        tick: float | None = None
        for batch in batches:
            if tick is None:
                tick = math.ceil(batch.stamp / period) * period
            while tick < batch.stamp:
                yield self.publish(tick)
                tick += period
            self.add(batch)
        if tick is not None and tick <= self.stamp:
            yield self.publish(tick)


def _header(stamp: float, seq: int, frame_id: str) -> dict[str, object]:
    sec = math.floor(stamp)
    nsec = min(round((stamp - sec) * 1e9), 999_999_999)
    return {"seq": seq, "stamp": {"sec": sec, "nsec": nsec}, "frame_id": frame_id}


def tracks_message(batch: TrackBatch) -> dict[str, object]:
    """OpenPTrack's tracks document (one UDP datagram)."""
    return {
        "header": _header(batch.stamp, batch.seq, "world"),
        "tracks": [
            {
                "id": t.id,
                "x": t.x,
                "y": t.y,
                "height": t.height,
                "age": t.age,
                "confidence": t.confidence,
            }
            for t in batch.tracks
        ],
    }


def heartbeat_message(beat: Heartbeat) -> dict[str, object]:
    """OpenPTrack's heartbeat document: the IDs alive and the largest ID given."""
    return {
        "header": _header(beat.stamp, beat.seq, "heartbeat"),
        "alive_IDs": list(beat.alive_ids),
        "max_ID": beat.max_id,
    }
