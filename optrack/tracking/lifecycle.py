"""Track life-cycle (Munaro 2012 section 5.4; OpenPTrack's ``Tracker::updateLostTracks``).

A track is born NEW from a detection no track took (with enough confidence),
is validated after ``detections_to_validate`` detections that confident (or, born
from weaker detections, after ``weak_detections_to_validate`` detections in a
row: seen weakly but steadily, like a person behind furniture; a weak
detection the detector flags partly out of the image weighs in a run as a
confident one), becomes NORMAL
``sec_remain_new`` after its birth, MISSING when no sensor has detected it for
``sec_before_missing``, and is deleted ``sec_before_old`` after its last
detection. A track never validated is deleted as fake ``sec_before_fake``
after its birth (OpenPTrack), or as soon as it goes missing: a person just
found is seen in every frame, a flickering false alarm is not.
"""

from __future__ import annotations

import bisect
import dataclasses
import enum
from typing import Any

import numpy as np

from optrack.types import TrackStatus

__all__ = [
    "Fate",
    "TrackState",
    "advance",
    "lost_at_the_edge",
    "on_detected",
    "on_missed",
    "record_position",
    "reference_position",
    "seen_near",
]


class Fate(enum.Enum):
    KEEP = "keep"
    FAKE = "fake"  # never validated in time
    OLD = "old"  # not detected for too long


@dataclasses.dataclass(eq=False)
class TrackState:
    """Everything the tracker keeps about one track (world frame, metres, seconds)."""

    id: int
    x: np.ndarray  # [x, y, vx, vy] at time t
    P: np.ndarray  # 4x4
    t: float
    born: float
    last_detection: float
    height: float
    confidence: float
    status: TrackStatus = TrackStatus.NEW
    validated: bool = False
    detections: int = 0
    confident_detections: int = 0  # with at least min_confidence_initialization
    #: per sensor, detections in a row, weighted by :func:`_run_weights` (reset by a frame of
    #: that sensor that misses the track)
    runs: dict[str, int] = dataclasses.field(default_factory=dict)
    streak: int = 0  # detections since the last gap of sec_before_missing
    confirmed: float = -np.inf  # last detection of a run long enough to trust
    sensors: dict[str, float] = dataclasses.field(default_factory=dict)
    #: filtered positions (t, x, y) after each update, in time order
    history: list[tuple[float, float, float]] = dataclasses.field(default_factory=list)
    #: appearance features of the first unoccluded detections (identity recovery)
    features: list[np.ndarray] = dataclasses.field(default_factory=list)
    recovery_done: bool = False
    #: the latest detection the detector did not flag ``out_of_view`` (cut by the image's edge)
    seen_in_view: float = -np.inf

    def position_at(self, t: float) -> tuple[float, float]:
        """Constant-velocity extrapolation of the filtered position to time t."""
        dt = t - self.t
        return float(self.x[0] + dt * self.x[2]), float(self.x[1] + dt * self.x[3])


def on_detected(
    track: TrackState,
    t: float,
    confidence: float,
    height: float,
    sensor: str,
    params: Any,
    hidden: bool = False,
    out_of_view: bool = False,
) -> None:
    """A detection (stamped t, possibly late) was associated to the track.

    ``hidden``: the detector flagged the detection partly hidden in a way that
    explains a weak confidence (``out_of_view``: partly outside the image; see
    ``explained_weak_detections``): in a run it weighs as a confident detection.
    ``out_of_view``: the detector flagged it partly outside the image (see
    :func:`lost_at_the_edge`).
    """
    if not out_of_view:
        track.seen_in_view = max(track.seen_in_view, t)
    track.detections += 1
    confident = confidence >= params.min_confidence_initialization
    if confident:
        track.confident_detections += 1
    if t - track.last_detection >= params.sec_before_missing:
        track.streak = 0  # seen again after a gap: a new run of detections
        track.runs.clear()  # (also of a sensor gone silent meanwhile)
    track.streak += 1
    track.last_detection = max(track.last_detection, t)
    track.sensors[sensor] = max(track.sensors.get(sensor, t), t)
    weak_floor = min(
        params.min_confidence_initialization, params.min_confidence_weak_initialization
    )
    strong_weight, weak_weight, run_to_validate = _run_weights(params)
    if confidence >= weak_floor:
        weight = strong_weight if confident or hidden else weak_weight
        track.runs[sensor] = track.runs.get(sensor, 0) + weight
    track.confidence = confidence
    track.height += (height - track.height) / track.detections
    steady = sum(track.runs.values()) >= run_to_validate
    if not track.validated and (
        track.confident_detections >= params.detections_to_validate or steady
    ):
        track.validated = True
    # found again after a gap: seen once as many detections in a row as a new track needs
    if track.streak >= params.detections_to_validate or steady or not track.validated:
        track.confirmed = track.last_detection
    if track.confirmed >= track.last_detection:
        track.status = (
            TrackStatus.NORMAL
            if track.last_detection - track.born >= params.sec_remain_new
            else TrackStatus.NEW
        )


def _run_weights(params: Any) -> tuple[int, int, int]:
    """(strong weight, weak weight, run that validates), integers: a weak, unexplained
    detection weighs 1 / weak_detections_to_validate of a validating run, a confident or
    explained one 1 / detections_to_validate (of the two counts, the smaller)."""
    strong_needed = min(params.detections_to_validate, params.weak_detections_to_validate)
    weak_needed = params.weak_detections_to_validate
    # 1/strong_needed and 1/weak_needed, both scaled by strong_needed * weak_needed
    strong_weight, weak_weight = weak_needed, strong_needed
    return strong_weight, weak_weight, weak_needed * strong_needed


def on_missed(track: TrackState, sensor: str, t: float) -> None:
    """A frame of ``sensor`` stamped t did not detect the track: the sensor's run of
    detections in a row starts over (only frames after its last detection of the track
    count; a late frame does not)."""
    if track.runs.get(sensor) and track.sensors[sensor] < t:
        track.runs[sensor] = 0


def advance(track: TrackState, now: float, params: Any) -> Fate:
    """Update the status with the time ``now``; say whether the track lives on.

    A track found again after it went missing is seen (and kept alive) only
    once ``detections_to_validate`` detections in a row confirm it: one stray
    detection (a false alarm in its wide gate) does not keep a lost track.

    With ``out_of_view_hold`` on, a validated track lost at the image's edge
    (:func:`lost_at_the_edge`) goes MISSING after ``sec_before_missing_out_of_view``
    rather than ``sec_before_missing``: the detector gives up on a person at the image's edge while much of them is still in the
    image. Only the status changes (what the output smoother holds); association and
    deletion go by the time unseen as for any track.
    """
    unseen = now - track.last_detection
    if not track.validated and (
        now - track.born >= params.sec_before_fake or unseen >= params.sec_before_missing
    ):
        return Fate.FAKE
    if now - track.confirmed >= params.sec_before_old:
        return Fate.OLD
    missing_after = params.sec_before_missing
    if params.out_of_view_hold == "on" and lost_at_the_edge(track, params):
        missing_after = max(missing_after, params.sec_before_missing_out_of_view)
    if unseen >= missing_after or track.confirmed < track.last_detection:
        track.status = TrackStatus.MISSING
    return Fate.KEEP


def lost_at_the_edge(track: TrackState, params: Any) -> bool:
    """Whether every detection of the track's last ``sec_before_missing`` (before it was
    last detected) was flagged ``out_of_view``: every sensor that saw the person at the
    end saw them cut by its image's edge. One detection in full view among them (another
    sensor still sees the person, who is lost for another reason) says no."""
    return track.last_detection - track.seen_in_view >= params.sec_before_missing


def record_position(track: TrackState, t: float, keep: float) -> None:
    """Add the filtered position at t (the state carried back from its own time if t is
    earlier) to the history, in time order; forget entries older than ``keep`` seconds
    before the newest, keeping one such entry."""
    x, y = track.position_at(t)
    entry = (t, x, y)
    history = track.history
    if not history or t >= history[-1][0]:
        history.append(entry)
    else:
        bisect.insort(history, entry)
    cutoff = history[-1][0] - keep
    drop = 0
    while drop + 1 < len(history) and history[drop + 1][0] <= cutoff:
        drop += 1
    if drop:
        del history[:drop]


def reference_position(track: TrackState, t: float, baseline: float) -> tuple[float, float, float]:
    """The latest filtered position at least ``baseline`` before t: (x, y, age).

    Age is NaN when the track has no position that old (its velocity is then
    not measured).
    """
    history = track.history
    k = bisect.bisect_right(history, (t - baseline, np.inf, np.inf)) - 1
    if k < 0:
        return 0.0, 0.0, float("nan")
    ht, hx, hy = history[k]
    return hx, hy, t - ht


def seen_near(track: TrackState, t: float) -> tuple[float, float, float]:
    """Where the track was detected closest before t (or first, for t before its history),
    and how long before (or after) t: (x, y, |dt|)."""
    history = track.history
    if not history:
        return float(track.x[0]), float(track.x[1]), abs(t - track.t)
    k = bisect.bisect_right(history, (t, np.inf, np.inf)) - 1
    ht, hx, hy = history[max(k, 0)]
    return hx, hy, abs(t - ht)
