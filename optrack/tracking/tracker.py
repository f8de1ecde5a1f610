"""The central tracker: every sensor's detection batches in, tracks out.

Each :meth:`Tracker.update` takes one :class:`~optrack.types.DetectionBatch`
(sensors are asynchronous, so batches come one at a time) and, as
OpenPTrack's ``Tracker::updateTracks``:

1. predicts every track to the batch's stamp (UKF, :mod:`.motion`);
2. builds ``z = [x, y, vx, vy]`` and ``R`` for every (track, detection) pair,
   the Mahalanobis ``d2`` and the gate (:mod:`.association`);
3. assigns detections to tracks (``linear_sum_assignment``), then, with
   appearance on, gives detections the gate left over to lost tracks whose
   colour classifier recognises them (:mod:`.appearance`);
4. updates the assigned tracks, starts tracks from confident detections left
   over, gives a recently lost identity back to a new track its classifier
   recognises, and runs the life-cycle (:mod:`.lifecycle`).

A batch up to ``max_detection_delay`` behind the newest one is used: its
detections are carried forward to each track's own time along the track's
velocity, with the noise that adds (an out-of-sequence measurement by
measurement extrapolation), so the tracks' states never go back in time.
Older batches are dropped and counted in :meth:`Tracker.status`.
"""

from __future__ import annotations

import collections
import dataclasses
import math
import types

import numpy as np

from optrack.errors import UserError
from optrack.params import Params
from optrack.tracking.appearance import AppearanceModel
from optrack.tracking.association import (
    assign,
    association_cost,
    extrapolate_late,
    gate_value,
    mahalanobis,
    measurement_noise,
    measurements,
    reach,
    weak_revival,
    within_reach,
)
from optrack.tracking.lifecycle import (
    Fate,
    TrackState,
    advance,
    on_detected,
    on_missed,
    record_position,
    reference_position,
    seen_near,
)
from optrack.tracking.motion import ConstantVelocityUKF, position_variance
from optrack.tracking.params import APPEARANCE_PARAMS, TRACKING_PARAMS
from optrack.types import Detection, DetectionBatch, Track, TrackBatch

__all__ = ["Tracker", "TrackerStatus", "TrackingError"]


class TrackingError(UserError):
    """Detections the tracker cannot use."""


@dataclasses.dataclass
class TrackerStatus:
    """What the tracker reports about itself (the GUI and the status topic show it)."""

    stamp: float
    tracks: int
    published: int
    batches: int
    dropped_batches: int
    dropped_by_sensor: dict[str, int]
    sensors: dict[str, float]  # sensor -> stamp of its last batch
    silent_sensors: list[str]
    appearance: bool
    recovered_identities: int  # new tracks given a lost identity back
    appearance_matches: int  # detections given to lost tracks by appearance alone
    warnings: list[str]


class Tracker:
    """Multi-sensor people tracker on the ground plane (OpenPTrack section 6, Munaro 2012)."""

    def __init__(
        self,
        params: Params | None = None,
        appearance_params: Params | None = None,
        sensors: int | None = None,
    ) -> None:
        """``sensors``: how many sensors feed the tracker, when known (appearance 'auto')."""
        self.params = params if params is not None else TRACKING_PARAMS.create()
        self.appearance_params = (
            appearance_params if appearance_params is not None else APPEARANCE_PARAMS.create()
        )
        self.sensor_count = sensors
        self.tracks: list[TrackState] = []
        self.next_id = 1
        self.clock = -math.inf
        self.seq = 0
        self.batches = 0
        self.dropped = 0
        self.dropped_by_sensor: collections.Counter[str] = collections.Counter()
        self.sensor_last: dict[str, float] = {}
        self.recovered = 0
        self.appearance_matches = 0
        self.appearance = AppearanceModel(self.appearance_params)
        self._derived_key: tuple[object, ...] = ()
        self._refresh()

    # ---------------------------------------------------------------- settings
    def _refresh(self) -> None:
        """Recompute what derives from parameters (they can change live); ``self.p`` is a
        plain snapshot of them for the hot loops."""
        self.p = types.SimpleNamespace(**self.params.as_dict())
        p = self.p
        key = (
            p.gate_probability,
            p.acceleration_variance,
            p.acceleration_rate,
            p.ukf_alpha,
            p.ukf_beta,
            p.ukf_kappa,
        )
        if key != self._derived_key:
            self.ukf = ConstantVelocityUKF(p)
            self.gate = gate_value(p.gate_probability)
            self._derived_key = key

    @property
    def appearance_enabled(self) -> bool:
        mode = self.params.appearance
        if mode != "auto":
            return mode == "on"
        count = self.sensor_count if self.sensor_count is not None else len(self.sensor_last)
        return count <= 1

    @property
    def out_of_view_hold(self) -> bool:
        """Whether a track lost at the image's edge is held (``out_of_view_hold``)."""
        return self.params.out_of_view_hold == "on"

    # ------------------------------------------------------------------ update
    def update(self, batch: DetectionBatch, now: float | None = None) -> TrackBatch | None:
        """Process one batch; return the tracks after it, or None when it was dropped.

        ``now`` is the time the batch is judged late against (default: the
        newest stamp seen, which makes replays deterministic).
        """
        self._refresh()
        p = self.p
        t = float(batch.stamp)
        if not math.isfinite(t):
            raise TrackingError(
                f"a detection batch of sensor '{batch.sensor_id}' has stamp {batch.stamp}; "
                "stamps must be finite seconds."
            )
        if batch.frame_id != "world":
            raise TrackingError(
                f"detections of sensor '{batch.sensor_id}' are in frame '{batch.frame_id}'; the "
                "tracker needs world-frame detections, so give the detector the calibration."
            )
        reference = max(self.clock, t) if now is None else now
        if reference - t > p.max_detection_delay:
            self.dropped += 1
            self.dropped_by_sensor[batch.sensor_id] += 1
            return None
        self.batches += 1
        self.clock = max(self.clock, t)
        self.sensor_last[batch.sensor_id] = max(self.sensor_last.get(batch.sensor_id, t), t)

        detections = [
            d
            for d in batch.detections
            if d.confidence >= p.min_confidence_detections
            and math.isfinite(d.x)
            and math.isfinite(d.y)
        ]
        m = len(detections)
        positions = np.array([(d.x, d.y) for d in detections], dtype=np.float64).reshape(m, 2)
        confidence = np.array([d.confidence for d in detections], dtype=np.float64)
        position_var = position_variance(_sensor_distances(detections), p)
        appearance = self.appearance_enabled
        # an occluded detection's colours are partly someone else's or something else's:
        # no appearance for it
        features = (
            self.appearance.features([[] if d.occluded else d.histogram for d in detections])
            if appearance and m
            else None
        )

        self._advance(self.clock)  # statuses at this time; tracks whose time is up go
        taken = np.zeros(m, dtype=bool)
        explained = np.zeros(m, dtype=bool)
        if self.tracks and m:
            taken, explained = self._associate(
                t, batch.sensor_id, detections, positions, confidence, position_var, features
            )
        self._start_tracks(
            t, batch.sensor_id, detections, positions, position_var, features, taken, explained
        )
        for track in self.tracks:
            on_missed(track, batch.sensor_id, t)
        if appearance and features is not None:
            self._recover_identities(t)
        return self.output(self.clock)

    def _associate(
        self,
        t: float,
        sensor: str,
        detections: list[Detection],
        positions: np.ndarray,
        confidence: np.ndarray,
        position_var: np.ndarray,
        features: np.ndarray | None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Steps 1-3 and the updates; returns which detections were taken, and which lie
        in some track's gates (a person already tracked could explain them)."""
        p = self.p
        tracks = self.tracks
        n, m = len(tracks), len(detections)
        X = np.array([tr.x for tr in tracks])
        P = np.array([tr.P for tr in tracks])
        dt = np.array([t - tr.t for tr in tracks])
        # a batch older than a track's state is carried forward to it (late: lag > 0)
        lag = np.maximum(-dt, 0.0)
        x_prior, P_prior = self.ukf.predict(X, P, np.maximum(dt, 0.0))
        zp, S0, Pxz = self.ukf.innovation(x_prior, P_prior)
        refs = [reference_position(tr, t, p.velocity_baseline) for tr in tracks]
        reference = np.array([(r[0], r[1]) for r in refs]).reshape(n, 2)
        baseline = np.array([r[2] for r in refs])
        z = measurements(positions, reference, baseline, zp)
        R = measurement_noise(position_var, baseline, self.ukf.spectral_density)
        if lag.any():
            extrapolate_late(z, R, lag, x_prior, P_prior, self.ukf.spectral_density)
        S = S0[:, None] + R
        z_tilde = z - zp[:, None, :]
        d2, logdet = mahalanobis(z_tilde, S)
        seen = [seen_near(tr, t) for tr in tracks]
        last_seen = np.array([(s[0], s[1]) for s in seen]).reshape(n, 2)
        unseen = np.array([s[2] for s in seen])
        allowed = (d2 <= self.gate) & within_reach(
            positions, last_seen, unseen, p.max_speed, p.min_reach
        )
        # a weak detection some track (even a lost one) could take is no new person
        explained = allowed.any(axis=0)
        # a detection too weak to start a confident track cannot revive a missing one, unless
        # the detector explains its weakness and the track, lost moments ago, predicts the
        # person right there (someone stepping out from behind someone else)
        missing = np.array([t - tr.confirmed for tr in tracks]) >= p.sec_before_missing
        weak = confidence < p.min_confidence_initialization
        barred = missing[:, None] & weak[None, :]
        if barred.any():
            hidden = np.array([_hidden(d, "out_of_view_or_occluded") for d in detections])
            barred &= ~weak_revival(
                positions, hidden, x_prior[:, 0:2], unseen, p.sec_weak_revival, p.min_reach
            )
            allowed &= ~barred
        if features is not None:
            # a person lost for long is not given someone their classifier clearly rejects
            lost = self._missing_candidates(t, set())
            if lost:
                looks = np.array([self.appearance.confidence(tracks[i].id, features) for i in lost])
                allowed[lost] &= looks >= -self.appearance_params.min_confidence
        cost = association_cost(d2, logdet, confidence, p.motion_weight, p.detector_weight)
        pairs = assign(cost, allowed)

        taken = np.zeros(m, dtype=bool)
        if pairs:
            ti = np.array([i for i, _ in pairs])
            dj = np.array([j for _, j in pairs])
            x_post, P_post = self.ukf.update(
                x_prior[ti], P_prior[ti], zp[ti], S[ti, dj], Pxz[ti], z[ti, dj]
            )
            for k, (i, j) in enumerate(pairs):
                self._take(
                    tracks[i], max(tracks[i].t, t), x_post[k], P_post[k], t, sensor, detections[j]
                )
                taken[j] = True

        if features is not None:
            recovered = self._appearance_step(
                t,
                sensor,
                detections,
                positions,
                position_var,
                features,
                taken,
                {i for i, _ in pairs},
            )
            for j in recovered:
                taken[j] = True
            self._learn(t, pairs, detections, features)
        return taken, explained

    def _take(
        self,
        track: TrackState,
        state_time: float,
        x: np.ndarray,
        P: np.ndarray,
        t: float,
        sensor: str,
        detection: Detection,
    ) -> None:
        track.x, track.P, track.t = x, P, state_time
        record_position(track, t, self.p.max_detection_delay + 2 * self.p.velocity_baseline)
        on_detected(
            track,
            t,
            detection.confidence,
            detection.height,
            sensor,
            self.p,
            _hidden(detection, self.p.explained_weak_detections),
            detection.out_of_view,
        )

    # -------------------------------------------------------------- appearance
    def _missing_candidates(self, t: float, skip: set[int]) -> list[int]:
        """Indices of validated tracks lost long enough to give their identity away."""
        wait = self.appearance_params.sec_missing_before_recovery
        return [
            i
            for i, tr in enumerate(self.tracks)
            if i not in skip
            and tr.validated
            and t - tr.confirmed >= wait
            and (c := self.appearance.classifiers.get(tr.id)) is not None
            and c.trained
        ]

    def _reach(self, lost_for: np.ndarray) -> np.ndarray:
        return reach(lost_for, self.p.max_speed, self.p.min_reach)

    def _appearance_step(
        self,
        t: float,
        sensor: str,
        detections: list[Detection],
        positions: np.ndarray,
        position_var: np.ndarray,
        features: np.ndarray,
        taken: np.ndarray,
        associated: set[int],
    ) -> list[int]:
        """Second association: detections the gate left over against lost tracks' classifiers.
        A detection too weak to start a track revives none here (the motion step's rule)
        unless the detector's flags explain its weakness (``explained_weak_detections``; the
        motion step has no such exception): the detector's weak false alarms (furniture)
        would otherwise take the colours of someone lost."""
        p = self.p
        usable = np.array(
            [
                d.confidence >= p.min_confidence_initialization
                or _hidden(d, p.explained_weak_detections)
                for d in detections
            ],
            dtype=bool,
        )
        free = np.flatnonzero(~taken & usable)
        candidates = self._missing_candidates(t, associated)
        if not free.size or not candidates:
            return []
        conf = np.array(
            [self.appearance.confidence(self.tracks[i].id, features[free]) for i in candidates]
        )
        last = np.array([_last_seen(self.tracks[i]) for i in candidates])
        lost_for = np.array([t - self.tracks[i].confirmed for i in candidates])
        distance = np.linalg.norm(positions[free][None, :, :] - last[:, None, :], axis=2)
        allowed = (conf >= self.appearance_params.min_confidence) & (
            distance <= self._reach(lost_for)[:, None]
        )
        out = []
        for a, b in assign(-conf, allowed):
            track, j = self.tracks[candidates[a]], int(free[b])
            lost_since = track.confirmed
            x, P = self._initial_state(positions[j], position_var[j])
            self._take(track, max(track.t, t), x, P, t, sensor, detections[j])
            self._absorb_young(track, positions[j], lost_since)
            self.appearance_matches += 1
            out.append(j)
        return out

    def _absorb_young(self, track: TrackState, position: np.ndarray, lost_since: float) -> None:
        """A track started near a recovered person while they were lost is that person
        (its first detections were too occluded to recognise): merge it into the identity."""
        a = self.appearance_params
        for other in list(self.tracks):
            if other is track or other.born <= lost_since:
                continue
            ox, oy = _last_seen(other)
            if math.hypot(ox - position[0], oy - position[1]) > self.p.min_reach:
                continue
            if other.features:
                score = np.mean(self.appearance.confidence(track.id, np.array(other.features)))
                if score < a.min_confidence:
                    continue
            self.tracks.remove(other)
            self.appearance.drop(other.id)
            track.detections += other.detections
            track.confident_detections += other.confident_detections

    def _learn(
        self,
        t: float,
        pairs: list[tuple[int, int]],
        detections: list[Detection],
        features: np.ndarray,
    ) -> None:
        """Each associated, unoccluded detection teaches its track (and is kept for identity
        recovery among its first ones); the batch's others are negatives."""
        for i, j in pairs:
            track = self.tracks[i]
            if not np.all(np.isfinite(features[j])):
                continue  # occluded, or no histogram
            if len(track.features) < self.appearance_params.recovery_detections:
                track.features.append(features[j])
            self.appearance.learn(t, track.id, features[j], np.delete(features, j, axis=0))

    def _recover_identities(self, t: float) -> None:
        """Give a lost identity back to a new track its classifier recognises (Munaro 5.4),
        once the new track is validated: a false alarm (furniture) that happens to wear a
        lost person's colours must not become that person, shown at once. A track validated
        within its first ``recovery_detections`` detections is tried at each of them, one
        validated later (a weak run) once."""
        a = self.appearance_params
        for track in list(self.tracks):
            if track.recovery_done or track not in self.tracks or not track.validated:
                continue
            if not track.features:
                track.recovery_done = track.detections >= a.recovery_detections
                continue
            F = np.array(track.features)
            best: tuple[float, int | None, int] = (a.min_confidence, None, 0)
            here = np.array(track.history[0][1:] if track.history else track.x[:2])
            for other in self.tracks:
                if other is track or not other.validated or other.confirmed >= track.born:
                    continue
                if track.born - other.confirmed < a.sec_missing_before_recovery:
                    continue
                c = self.appearance.classifiers.get(other.id)
                if c is None or not c.trained:
                    continue
                last = np.array(_last_seen(other))
                reach = self._reach(np.array([track.born - other.confirmed]))[0]
                if np.linalg.norm(here - last) > reach:
                    continue
                score = float(np.mean(self.appearance.confidence(other.id, F)))
                if score >= best[0]:
                    best = (score, other.id, 0)
            for tid, lx, ly, last_detection in self.appearance.lost_candidates():
                if last_detection >= track.born:
                    continue
                reach = self._reach(np.array([track.born - last_detection]))[0]
                if np.hypot(here[0] - lx, here[1] - ly) > reach:
                    continue
                score = float(np.mean(self.appearance.lost_confidence(tid, F)))
                if score >= best[0]:
                    best = (score, tid, 1)
            if best[1] is not None:
                self._give_identity(track, best[1], from_deleted=bool(best[2]))
                track.recovery_done = True
            else:
                track.recovery_done = track.detections >= a.recovery_detections

    def _give_identity(self, track: TrackState, old_id: int, from_deleted: bool) -> None:
        self.appearance.drop(track.id)
        if from_deleted:
            classifier = self.appearance.take_lost(old_id)
        else:
            old = next(tr for tr in self.tracks if tr.id == old_id)
            self.tracks.remove(old)
            classifier = self.appearance.classifiers.pop(old_id, None)
            track.born = min(track.born, old.born)
            track.detections += old.detections
        track.id = old_id
        if classifier is not None:
            self.appearance.adopt(old_id, classifier)
        self.recovered += 1

    # ---------------------------------------------------------- birth, death
    def _initial_state(
        self, position: np.ndarray, position_var: float
    ) -> tuple[np.ndarray, np.ndarray]:
        x = np.array([position[0], position[1], 0.0, 0.0])
        v = self.p.initial_velocity_variance
        return x, np.diag([position_var, position_var, v, v])

    def _start_tracks(
        self,
        t: float,
        sensor: str,
        detections: list[Detection],
        positions: np.ndarray,
        position_var: np.ndarray,
        features: np.ndarray | None,
        taken: np.ndarray,
        explained: np.ndarray,
    ) -> None:
        p = self.p
        # confident detections start tracks that detections_to_validate such detections
        # validate; weaker ones, tracks that weak_detections_to_validate in a row validate,
        # and only where no track could explain them (a weak second detection of someone
        # tracked, from another sensor or a split silhouette, is not a new person)
        floor = min(p.min_confidence_initialization, p.min_confidence_weak_initialization)
        for j, d in enumerate(detections):
            if taken[j] or d.confidence < floor:
                continue
            if d.confidence < p.min_confidence_initialization and explained[j]:
                continue
            x, P = self._initial_state(positions[j], position_var[j])
            track = TrackState(
                id=self.next_id,
                x=x,
                P=P,
                t=t,
                born=t,
                last_detection=t,
                height=d.height,
                confidence=d.confidence,
            )
            self.next_id += 1
            record_position(track, t, p.max_detection_delay + 2 * p.velocity_baseline)
            on_detected(
                track,
                t,
                d.confidence,
                d.height,
                sensor,
                p,
                _hidden(d, p.explained_weak_detections),
                d.out_of_view,
            )
            if features is not None and np.all(np.isfinite(features[j])):
                track.features.append(features[j])
            self.tracks.append(track)

    def _advance(self, now: float) -> None:
        kept = []
        for track in self.tracks:
            fate = advance(track, now, self.p)
            if fate is Fate.KEEP:
                kept.append(track)
            elif fate is Fate.OLD:
                x, y = _last_seen(track)
                self.appearance.forget(track.id, x, y, track.confirmed, now)
            else:
                self.appearance.drop(track.id)
        self.tracks = kept

    # ------------------------------------------------------------------ output
    def output(self, t: float | None = None) -> TrackBatch:
        """Validated tracks, positions carried to time t (default: the newest stamp)."""
        t = self.clock if t is None else t
        self.seq += 1
        missing = self.p.sec_before_missing
        tracks = []
        for tr in self.tracks:
            if not tr.validated:
                continue
            x, y = tr.position_at(max(t, tr.t))
            tracks.append(
                Track(
                    id=tr.id,
                    x=x,
                    y=y,
                    height=float(tr.height),
                    vx=float(tr.x[2]),
                    vy=float(tr.x[3]),
                    age=float(t - tr.born),
                    confidence=float(tr.confidence),
                    status=tr.status,
                    sensors=sorted(s for s, ts in tr.sensors.items() if t - ts <= missing),
                )
            )
        return TrackBatch(stamp=float(t), seq=self.seq, tracks=tracks)

    def status(self, now: float | None = None) -> TrackerStatus:
        """Counters and warnings; a sensor silent for ``sensor_timeout`` is named."""
        now = self.clock if now is None else now
        silent = sorted(
            s for s, last in self.sensor_last.items() if now - last > self.params.sensor_timeout
        )
        warnings = [
            f"sensor '{s}' has sent no detections for {now - self.sensor_last[s]:.1f} s; "
            "check that its detector is running and its cable is in."
            for s in silent
        ]
        if self.dropped:
            warnings.append(
                f"{self.dropped} detection batches arrived more than "
                f"{self.params.max_detection_delay:g} s late and were dropped; check the clocks "
                "of the detector computers."
            )
        return TrackerStatus(
            stamp=now,
            tracks=len(self.tracks),
            published=sum(1 for tr in self.tracks if tr.validated),
            batches=self.batches,
            dropped_batches=self.dropped,
            dropped_by_sensor=dict(self.dropped_by_sensor),
            sensors=dict(self.sensor_last),
            silent_sensors=silent,
            appearance=self.appearance_enabled,
            recovered_identities=self.recovered,
            appearance_matches=self.appearance_matches,
            warnings=warnings,
        )


def _last_seen(track: TrackState) -> tuple[float, float]:
    """Where the track was last detected (its newest filtered position)."""
    if track.history:
        return track.history[-1][1], track.history[-1][2]
    return float(track.x[0]), float(track.x[1])


def _hidden(detection: Detection, explained: str) -> bool:
    """Whether the detector flagged the detection partly hidden in a way that explains a weak
    HOG margin (``explained_weak_detections``): partly outside the image, or also behind
    something nearer to the sensor."""
    if explained == "none":
        return False
    if explained == "out_of_view_or_occluded" and detection.occluded:
        return True
    return detection.out_of_view


def _sensor_distances(detections: list[Detection]) -> np.ndarray:
    """Distance of each detection from its sensor (0 when the camera-frame centroid is unknown)."""
    return np.array(
        [math.sqrt(sum(c * c for c in d.camera_xyz)) if d.camera_xyz else 0.0 for d in detections],
        dtype=np.float64,
    )
