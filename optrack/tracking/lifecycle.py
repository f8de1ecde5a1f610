"""Track life-cycle (Munaro 2012 section 5.4; OpenPTrack's ``Tracker::updateLostTracks``).

A track is born NEW from a detection no track took (with enough confidence),
is validated after ``detections_to_validate`` detections that confident (or, born
from weaker detections, after ``weak_detections_to_validate`` detections in a
row: seen weakly but steadily, like a person behind furniture; a weak
detection the detector's flags explain weighs in a run as a confident one),
becomes NORMAL ``sec_remain_new`` after its birth, MISSING when no sensor has
detected it for ``sec_before_missing``, and is deleted ``sec_before_old`` after
its last detection. A track never validated is deleted as fake
``sec_before_fake`` after its birth (OpenPTrack), or as soon as it goes
missing: a person just found is seen in every frame, a flickering false alarm
is not.

Every rule lives in :class:`LifecyclePolicy`, one typed value read from the
tracking parameters, with all the rules about weak detections (which start a
track, which weigh as confident in a run, which may revive a lost track or be
given to one by appearance) and the out-of-view hold. The detector's flags are
the members of :class:`Flag`.
"""

from __future__ import annotations

import bisect
import dataclasses
import enum
from typing import TYPE_CHECKING, Any

import numpy as np

from optrack.types import Detection, TrackStatus

if TYPE_CHECKING:
    from optrack.tracking.association import Candidates

__all__ = [
    "EXPLAINED_WEAK_DETECTIONS",
    "REVIVAL_FLAGS",
    "Fate",
    "Flag",
    "LifecyclePolicy",
    "TrackState",
    "record_position",
    "reference_position",
    "seen_near",
    "weak_revival",
]


class Flag(enum.StrEnum):
    """The detector's flags on a detection (each the name of a :class:`Detection` field)."""

    OCCLUDED = "occluded"  # part of the person is behind something nearer the sensor
    OUT_OF_VIEW = "out_of_view"  # part of the person is outside the image

    def on(self, detection: Detection) -> bool:
        """Whether the detector raised this flag on the detection."""
        return bool(getattr(detection, self._value_))


#: ``explained_weak_detections``'s choices: the flags that explain a weak HOG margin
EXPLAINED_WEAK_DETECTIONS: dict[str, frozenset[Flag]] = {
    "out_of_view": frozenset({Flag.OUT_OF_VIEW}),
    "out_of_view_or_occluded": frozenset({Flag.OUT_OF_VIEW, Flag.OCCLUDED}),
    "none": frozenset(),
}

#: the flags that let a weak detection revive a track lost moments ago (``sec_weak_revival``)
REVIVAL_FLAGS: frozenset[Flag] = frozenset(Flag)


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
    #: per sensor, detections in a row, weighted by :attr:`LifecyclePolicy.strong_weight` or ``weak_weight`` (reset
    #: by a frame of that sensor that misses the track)
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

    def last_seen(self) -> tuple[float, float]:
        """Where the track was last detected (its newest filtered position)."""
        if self.history:
            return self.history[-1][1], self.history[-1][2]
        return float(self.x[0]), float(self.x[1])


@dataclasses.dataclass(frozen=True)
class LifecyclePolicy:
    """The life-cycle's rules, read from the tracking parameters (:meth:`from_params`)."""

    min_confidence: float  # min_confidence_initialization: a confident detection
    min_confidence_weak: float  # min_confidence_weak_initialization
    detections_to_validate: int
    weak_detections_to_validate: int
    explaining_flags: frozenset[Flag]  # explained_weak_detections
    sec_remain_new: float
    sec_before_missing: float
    sec_before_fake: float
    sec_before_old: float
    sec_weak_revival: float
    revival_radius: float  # min_reach
    out_of_view_hold: bool
    sec_before_missing_out_of_view: float
    #: derived: the least confidence that starts a track or counts in a run
    weak_floor: float = dataclasses.field(init=False)
    #: derived: a validating run's weights
    strong_weight: int = dataclasses.field(init=False)
    weak_weight: int = dataclasses.field(init=False)
    run_to_validate: int = dataclasses.field(init=False)

    def __post_init__(self) -> None:
        # integers: a weak, unexplained detection weighs 1 / weak_detections_to_validate of a
        # validating run, a confident or explained one 1 / detections_to_validate (of the two
        # counts, the smaller); both scaled by the product of the two counts
        strong_needed = min(self.detections_to_validate, self.weak_detections_to_validate)
        weak_needed = self.weak_detections_to_validate
        object.__setattr__(self, "weak_floor", min(self.min_confidence, self.min_confidence_weak))
        object.__setattr__(self, "strong_weight", weak_needed)
        object.__setattr__(self, "weak_weight", strong_needed)
        object.__setattr__(self, "run_to_validate", weak_needed * strong_needed)

    @classmethod
    def from_params(cls, params: Any) -> LifecyclePolicy:
        """The policy of a ``tracking`` parameter set (or a snapshot of one)."""
        return cls(
            min_confidence=params.min_confidence_initialization,
            min_confidence_weak=params.min_confidence_weak_initialization,
            detections_to_validate=params.detections_to_validate,
            weak_detections_to_validate=params.weak_detections_to_validate,
            explaining_flags=EXPLAINED_WEAK_DETECTIONS[params.explained_weak_detections],
            sec_remain_new=params.sec_remain_new,
            sec_before_missing=params.sec_before_missing,
            sec_before_fake=params.sec_before_fake,
            sec_before_old=params.sec_before_old,
            sec_weak_revival=params.sec_weak_revival,
            revival_radius=params.min_reach,
            out_of_view_hold=params.out_of_view_hold == "on",
            sec_before_missing_out_of_view=params.sec_before_missing_out_of_view,
        )

    # ------------------------------------------------------------ weak detections
    def confident(self, detection: Detection) -> bool:
        return detection.confidence >= self.min_confidence

    def explained(self, detection: Detection) -> bool:
        """Whether the detector's flags explain a weak HOG margin (``explained_weak_detections``:
        part of the person outside the image, or also behind something nearer)."""
        return any(flag.on(detection) for flag in self.explaining_flags)

    def may_start(self, detection: Detection, near_a_track: bool) -> bool:
        """Whether a detection no track took starts a track. A weak one starts none where a
        track (even a lost one) could take it: a weak second detection of someone tracked,
        from another sensor or a split silhouette, or a lost person coming back, is no new
        person."""
        if detection.confidence < self.weak_floor:
            return False
        return self.confident(detection) or not near_a_track

    def may_be_recognised(self, detection: Detection) -> bool:
        """Whether appearance may give the detection to a lost track: a detection too weak
        to start a track only when its flags explain the weakness (the detector's weak false
        alarms, furniture, would otherwise take the colours of someone lost)."""
        return self.confident(detection) or self.explained(detection)

    def revival_barred(self, candidates: Candidates) -> np.ndarray:
        """(N, M) pairs association may not make: a detection too weak to start a confident
        track cannot revive a missing one, unless the detector explains its weakness
        (:data:`REVIVAL_FLAGS`) and the track, lost at most ``sec_weak_revival`` ago, predicts
        the person within ``min_reach`` of it: someone stepping out from behind someone else
        (:func:`weak_revival`)."""
        c = candidates
        missing = np.array([c.t - tr.confirmed for tr in c.tracks]) >= self.sec_before_missing
        weak = c.confidence < self.min_confidence
        barred = missing[:, None] & weak[None, :]
        if barred.any():
            hidden = np.array([any(f.on(d) for f in REVIVAL_FLAGS) for d in c.detections])
            barred &= ~weak_revival(
                c.positions,
                hidden,
                c.predicted[:, 0:2],
                c.unseen,
                self.sec_weak_revival,
                self.revival_radius,
            )
        return barred

    # --------------------------------------------------------------- the life-cycle
    def on_detected(self, track: TrackState, detection: Detection, t: float, sensor: str) -> None:
        """A detection (stamped t, possibly late) of ``sensor`` was associated to the track.

        A weak detection the policy :meth:`explained` weighs in a run as a confident one;
        one flagged ``out_of_view`` leaves ``seen_in_view`` (see :meth:`lost_at_the_edge`).
        """
        if not Flag.OUT_OF_VIEW.on(detection):
            track.seen_in_view = max(track.seen_in_view, t)
        track.detections += 1
        confident = self.confident(detection)
        if confident:
            track.confident_detections += 1
        if t - track.last_detection >= self.sec_before_missing:
            track.streak = 0  # seen again after a gap: a new run of detections
            track.runs.clear()  # (also of a sensor gone silent meanwhile)
        track.streak += 1
        track.last_detection = max(track.last_detection, t)
        track.sensors[sensor] = max(track.sensors.get(sensor, t), t)
        if detection.confidence >= self.weak_floor:
            strong = confident or self.explained(detection)
            weight = self.strong_weight if strong else self.weak_weight
            track.runs[sensor] = track.runs.get(sensor, 0) + weight
        track.confidence = detection.confidence
        track.height += (detection.height - track.height) / track.detections
        steady = sum(track.runs.values()) >= self.run_to_validate
        if not track.validated and (
            track.confident_detections >= self.detections_to_validate or steady
        ):
            track.validated = True
        # found again after a gap: seen once as many detections in a row as a new track needs
        if track.streak >= self.detections_to_validate or steady or not track.validated:
            track.confirmed = track.last_detection
        if track.confirmed >= track.last_detection:
            track.status = (
                TrackStatus.NORMAL
                if track.last_detection - track.born >= self.sec_remain_new
                else TrackStatus.NEW
            )

    @staticmethod
    def on_missed(track: TrackState, sensor: str, t: float) -> None:
        """A frame of ``sensor`` stamped t did not detect the track: the sensor's run of
        detections in a row starts over (only frames after its last detection of the track
        count; a late frame does not)."""
        if track.runs.get(sensor) and track.sensors[sensor] < t:
            track.runs[sensor] = 0

    def advance(self, track: TrackState, now: float) -> Fate:
        """Update the status with the time ``now``; say whether the track lives on.

        A track found again after it went missing is seen (and kept alive) only
        once ``detections_to_validate`` detections in a row confirm it: one stray
        detection (a false alarm in its wide gate) does not keep a lost track.

        With the out-of-view hold on, a validated track lost at the image's edge
        (:meth:`lost_at_the_edge`) goes MISSING after ``sec_before_missing_out_of_view``
        rather than ``sec_before_missing``: the detector gives up on a person at the image's
        edge while much of them is still in the image. Only the status changes (what the
        output smoother holds); association and deletion go by the time unseen as for any
        track.
        """
        unseen = now - track.last_detection
        if not track.validated and (
            now - track.born >= self.sec_before_fake or unseen >= self.sec_before_missing
        ):
            return Fate.FAKE
        if now - track.confirmed >= self.sec_before_old:
            return Fate.OLD
        missing_after = self.sec_before_missing
        if self.out_of_view_hold and self.lost_at_the_edge(track):
            missing_after = max(missing_after, self.sec_before_missing_out_of_view)
        if unseen >= missing_after or track.confirmed < track.last_detection:
            track.status = TrackStatus.MISSING
        return Fate.KEEP

    def lost_at_the_edge(self, track: TrackState) -> bool:
        """Whether every detection of the track's last ``sec_before_missing`` (before it was
        last detected) was flagged ``out_of_view``: every sensor that saw the person at the
        end saw them cut by its image's edge. One detection in full view among them (another
        sensor still sees the person, who is lost for another reason) says no."""
        return track.last_detection - track.seen_in_view >= self.sec_before_missing


def weak_revival(
    positions: np.ndarray,
    hidden: np.ndarray,
    predicted: np.ndarray,
    unseen: np.ndarray,
    window: float,
    radius: float,
) -> np.ndarray:
    """(N, M) pairs where a detection too weak to start a track may still take a missing one.

    Someone who steps out from behind another person or piece of furniture is
    detected weakly at first, and the detector says why (``hidden`` (M,): flagged
    occluded or partly outside the image). Such a detection may take a track lost
    for at most ``window`` seconds (``unseen`` (N,)) that predicts the person
    within ``radius`` of it (``predicted`` (N, 2)). Anything else weak still cannot
    revive a lost track: furniture's weak false alarms would keep it alive.
    """
    if window <= 0:
        return np.zeros((len(predicted), len(positions)), dtype=bool)
    distance = np.linalg.norm(positions[None, :, :] - predicted[:, None, :], axis=2)
    return (unseen <= window)[:, None] & hidden[None, :] & (distance <= radius)


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
