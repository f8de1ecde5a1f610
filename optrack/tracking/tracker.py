"""The central tracker: every sensor's detection batches in, tracks out.

Each :meth:`Tracker.update` takes one :class:`~optrack.types.DetectionBatch`
(sensors are asynchronous, so batches come one at a time) and, as
OpenPTrack's ``Tracker::updateTracks``:

1. predicts every track to the batch's stamp (UKF, :mod:`.motion`);
2. builds ``z = [x, y, vx, vy]`` and ``R`` for every (track, detection) pair and
   the Mahalanobis ``d2``; the gate says which pairs may be made, the cost what
   each costs (both swappable: ``Tracker(cost=..., gate=...)``; defaults in
   :mod:`.association`), and the life-cycle policy forbids what its rules forbid
   (:mod:`.lifecycle`);
3. assigns detections to tracks (``linear_sum_assignment``), then, with
   appearance on, gives detections the gate left over to lost tracks whose
   colour classifier recognises them (:mod:`.recovery`);
4. updates the assigned tracks, starts tracks from detections left over that the
   policy lets start one, gives a recently lost identity back to a new track its
   classifier recognises, and runs the life-cycle.

A batch up to ``max_detection_delay`` behind the newest one is used: its
detections are carried forward to each track's own time along the track's
velocity, with the noise that adds (an out-of-sequence measurement by
measurement extrapolation), so the tracks' states never go back in time.
Older batches are dropped and counted in :meth:`Tracker.status`.
"""

from __future__ import annotations

import collections
import dataclasses
import functools
import math
import types

import numpy as np

from optrack.errors import UserError
from optrack.params import Params, Value
from optrack.tracking.association import (
    Candidates,
    Cost,
    Gate,
    associate,
    chi_square_gate,
    extrapolate_late,
    gate_value,
    likelihood_cost,
    mahalanobis,
    measurement_noise,
    measurements,
    reach,
)
from optrack.tracking.lifecycle import (
    Fate,
    LifecyclePolicy,
    TrackState,
    record_position,
    reference_position,
    seen_near,
)
from optrack.tracking.motion import DEFAULT_VOXEL_SIZE, ConstantVelocityUKF, position_variance
from optrack.tracking.params import APPEARANCE_PARAMS, TRACKING_PARAMS
from optrack.tracking.recovery import IdentityRecovery
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


@dataclasses.dataclass(slots=True)
class _Batch:
    """The detections of one batch the tracker uses, with what it derives from them."""

    sensor: str
    t: float
    detections: list[Detection]
    positions: np.ndarray  # (M, 2)
    confidence: np.ndarray  # (M,)
    position_var: np.ndarray  # (M,)
    features: np.ndarray | None  # (M, K) colour features, appearance on


@dataclasses.dataclass(slots=True)
class _Motion:
    """The UKF's prior and innovation for every (track, detection) pair of a batch."""

    x_prior: np.ndarray  # (N, 4)
    P_prior: np.ndarray  # (N, 4, 4)
    zp: np.ndarray  # (N, 4)
    Pxz: np.ndarray  # (N, 4, 4)
    z: np.ndarray  # (N, M, 4)
    S: np.ndarray  # (N, M, 4, 4)
    d2: np.ndarray  # (N, M)
    logdet: np.ndarray  # (N, M)


class Tracker:
    """Multi-sensor people tracker on the ground plane (OpenPTrack section 6, Munaro 2012).

    ``cost`` and ``gate`` replace the association's cost and gate (see
    :class:`~optrack.tracking.association.Candidates`); by default
    :func:`~optrack.tracking.association.likelihood_cost` and
    :func:`~optrack.tracking.association.chi_square_gate`. ``gate`` is kept as
    :attr:`gate_rule`; :attr:`gate` is the chi-square bound on ``d2`` of the
    ``gate_probability`` parameter.
    """

    def __init__(
        self,
        params: Params | None = None,
        appearance_params: Params | None = None,
        sensors: int | None = None,
        *,
        cost: Cost = likelihood_cost,
        gate: Gate = chi_square_gate,
    ) -> None:
        """``sensors``: how many sensors feed the tracker, when known (appearance 'auto')."""
        self.params = params if params is not None else TRACKING_PARAMS.create()
        self.appearance_params = (
            appearance_params if appearance_params is not None else APPEARANCE_PARAMS.create()
        )
        self.cost = cost
        self.gate_rule = gate
        self.sensor_count = sensors
        self.tracks: list[TrackState] = []
        self.next_id = 1
        self.clock = -math.inf
        self.seq = 0
        self.batches = 0
        self.dropped = 0
        self.dropped_by_sensor: collections.Counter[str] = collections.Counter()
        self.sensor_last: dict[str, float] = {}
        self.recovery = IdentityRecovery(self.appearance_params)
        self._settings: dict[str, Value] = {}
        self._derived_key: tuple[object, ...] = ()
        self._refresh()

    # ---------------------------------------------------------------- settings
    def _refresh(self) -> None:
        """Recompute what derives from parameters (they can change live): ``self.p``, a
        plain snapshot of them for the hot loops, the life-cycle ``policy``, the UKF and
        the gate."""
        settings = self.params.as_dict()
        if settings == self._settings:
            return
        self._settings = settings
        self.p = p = types.SimpleNamespace(**settings)
        self.policy = LifecyclePolicy.from_params(p)
        self.reach = functools.partial(reach, max_speed=p.max_speed, min_reach=p.min_reach)
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
        t = float(batch.stamp)
        _check(batch, t)
        reference = max(self.clock, t) if now is None else now
        if reference - t > self.p.max_detection_delay:
            self.dropped += 1
            self.dropped_by_sensor[batch.sensor_id] += 1
            return None
        self.batches += 1
        self.clock = max(self.clock, t)
        self.sensor_last[batch.sensor_id] = max(self.sensor_last.get(batch.sensor_id, t), t)

        obs = self._usable(batch, t)
        m = len(obs.detections)
        self._advance(self.clock)  # statuses at this time; tracks whose time is up go
        taken = np.zeros(m, dtype=bool)
        explained = np.zeros(m, dtype=bool)
        if self.tracks and m:
            taken, explained = self._associate(obs)
        self._start_tracks(obs, taken, explained)
        on_missed = self.policy.on_missed
        for track in self.tracks:
            on_missed(track, obs.sensor, t)
        if obs.features is not None:
            self.recovery.recover_identities(self.tracks, t, self.reach)
        return self.output(self.clock)

    def _usable(self, batch: DetectionBatch, t: float) -> _Batch:
        """The batch's detections confident enough and on the ground, and their features
        when appearance is on."""
        p = self.p
        detections = [
            d
            for d in batch.detections
            if d.confidence >= p.min_confidence_detections
            and math.isfinite(d.x)
            and math.isfinite(d.y)
        ]
        m = len(detections)
        return _Batch(
            sensor=batch.sensor_id,
            t=t,
            detections=detections,
            positions=np.array([(d.x, d.y) for d in detections], dtype=np.float64).reshape(m, 2),
            confidence=np.array([d.confidence for d in detections], dtype=np.float64),
            position_var=position_variance(
                _sensor_distances(detections), p, batch.voxel_size or DEFAULT_VOXEL_SIZE
            ),
            features=(
                self.recovery.features(detections) if self.appearance_enabled and m else None
            ),
        )

    # ------------------------------------------------------------- association
    def _predict(self, obs: _Batch) -> _Motion:
        """Step 1 and the measurements of step 2 for every pair."""
        p, t, tracks = self.p, obs.t, self.tracks
        n = len(tracks)
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
        z = measurements(obs.positions, reference, baseline, zp)
        R = measurement_noise(obs.position_var, baseline, self.ukf.spectral_density)
        if lag.any():
            extrapolate_late(z, R, lag, x_prior, P_prior, self.ukf.spectral_density)
        S = S0[:, None] + R
        d2, logdet = mahalanobis(z - zp[:, None, :], S)
        return _Motion(x_prior, P_prior, zp, Pxz, z, S, d2, logdet)

    def _associate(self, obs: _Batch) -> tuple[np.ndarray, np.ndarray]:
        """Steps 1-3 and the updates; returns which detections were taken, and which lie
        in some track's gates (a person already tracked could explain them)."""
        tracks, t = self.tracks, obs.t
        motion = self._predict(obs)
        seen = [seen_near(tr, t) for tr in tracks]
        candidates = Candidates(
            t=t,
            tracks=tracks,
            detections=obs.detections,
            positions=obs.positions,
            confidence=obs.confidence,
            predicted=motion.x_prior,
            d2=motion.d2,
            logdet=motion.logdet,
            last_seen=np.array([(s[0], s[1]) for s in seen]).reshape(len(tracks), 2),
            unseen=np.array([s[2] for s in seen]),
            chi_square=self.gate,
            settings=self.p,
        )
        allowed = np.array(self.gate_rule(candidates), dtype=bool)
        # a weak detection some track (even a lost one) could take is no new person
        explained = allowed.any(axis=0)
        allowed &= ~self.policy.revival_barred(candidates)
        if obs.features is not None:
            # a person lost for long is not given someone their classifier clearly rejects
            rejected = self.recovery.rejected(tracks, t, obs.features)
            if rejected is not None:
                allowed &= ~rejected
        pairs = associate(candidates, self.cost, allowed)
        matched = [(tracks[i], j) for i, j in pairs]
        taken = np.zeros(len(obs.detections), dtype=bool)
        if pairs:
            self._update_pairs(obs, motion, pairs)
            taken[[j for _, j in pairs]] = True
        if obs.features is not None:
            self._appearance_step(obs, taken, {i for i, _ in pairs})
            self.recovery.learn(t, matched, obs.features)
        return taken, explained

    def _update_pairs(self, obs: _Batch, motion: _Motion, pairs: list[tuple[int, int]]) -> None:
        """The UKF update of every associated track with its detection."""
        ti = np.array([i for i, _ in pairs])
        dj = np.array([j for _, j in pairs])
        m = motion
        x_post, P_post = self.ukf.update(
            m.x_prior[ti], m.P_prior[ti], m.zp[ti], m.S[ti, dj], m.Pxz[ti], m.z[ti, dj]
        )
        for k, (i, j) in enumerate(pairs):
            track = self.tracks[i]
            self._take(track, max(track.t, obs.t), x_post[k], P_post[k], obs, j)

    def _appearance_step(self, obs: _Batch, taken: np.ndarray, associated: set[int]) -> None:
        """Second association: detections the gate left over (and the policy lets a lost
        track take) against lost tracks' classifiers; each taken one restarts its track's
        state there, and merges a track started on that person while they were lost."""
        assert obs.features is not None
        usable = np.array([self.policy.may_be_recognised(d) for d in obs.detections], dtype=bool)
        free = np.flatnonzero(~taken & usable)
        matches = self.recovery.match_lost(
            self.tracks, obs.t, obs.positions, obs.features, free, associated, self.reach
        )
        for track, j in matches:
            lost_since = track.confirmed
            x, P = self._initial_state(obs.positions[j], obs.position_var[j])
            self._take(track, max(track.t, obs.t), x, P, obs, j)
            self.recovery.absorb_young(
                self.tracks, track, obs.positions[j], lost_since, self.p.min_reach
            )
            taken[j] = True

    def _take(
        self,
        track: TrackState,
        state_time: float,
        x: np.ndarray,
        P: np.ndarray,
        obs: _Batch,
        j: int,
    ) -> None:
        """The track's new state, after detection j of the batch."""
        track.x, track.P, track.t = x, P, state_time
        self._record(track, obs, j)

    def _record(self, track: TrackState, obs: _Batch, j: int) -> None:
        """Detection j of the batch is the track's: its history and its life-cycle."""
        record_position(track, obs.t, self.p.max_detection_delay + 2 * self.p.velocity_baseline)
        self.policy.on_detected(track, obs.detections[j], obs.t, obs.sensor)

    # ---------------------------------------------------------- birth, death
    def _initial_state(
        self, position: np.ndarray, position_var: float
    ) -> tuple[np.ndarray, np.ndarray]:
        x = np.array([position[0], position[1], 0.0, 0.0])
        v = self.p.initial_velocity_variance
        return x, np.diag([position_var, position_var, v, v])

    def _start_tracks(self, obs: _Batch, taken: np.ndarray, explained: np.ndarray) -> None:
        """A track from every detection left over that the policy lets start one."""
        for j, d in enumerate(obs.detections):
            if taken[j] or not self.policy.may_start(d, near_a_track=bool(explained[j])):
                continue
            x, P = self._initial_state(obs.positions[j], obs.position_var[j])
            track = TrackState(
                id=self.next_id,
                x=x,
                P=P,
                t=obs.t,
                born=obs.t,
                last_detection=obs.t,
                height=d.height,
                confidence=d.confidence,
            )
            self.next_id += 1
            self._record(track, obs, j)
            if obs.features is not None:
                self.recovery.note_birth(track, obs.features[j])
            self.tracks.append(track)

    def _advance(self, now: float) -> None:
        kept = []
        for track in self.tracks:
            fate = self.policy.advance(track, now)
            if fate is Fate.KEEP:
                kept.append(track)
            elif fate is Fate.OLD:
                self.recovery.forget(track, now)
            else:
                self.recovery.drop(track)
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
            recovered_identities=self.recovery.recovered,
            appearance_matches=self.recovery.matches,
            warnings=warnings,
        )


def _check(batch: DetectionBatch, t: float) -> None:
    """Refuse a batch the tracker cannot use, with a sentence."""
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


def _sensor_distances(detections: list[Detection]) -> np.ndarray:
    """Distance of each detection from its sensor (0 when the camera-frame centroid is unknown)."""
    return np.array(
        [math.sqrt(sum(c * c for c in d.camera_xyz)) if d.camera_xyz else 0.0 for d in detections],
        dtype=np.float64,
    )
