"""Identity recovery by appearance (Munaro 2012 section 5.4).

:class:`IdentityRecovery` owns the colour classifiers (:mod:`.appearance`) and
uses them for identities lost for more than ``sec_missing_before_recovery``:

1. in the motion association, a lost track is not given a detection its
   classifier clearly rejects (:meth:`IdentityRecovery.rejected`);
2. a second association step gives detections the gates left over to lost
   tracks whose classifier recognises them (:meth:`IdentityRecovery.match_lost`),
   and a track started meanwhile on that person is merged into the identity
   (:meth:`IdentityRecovery.absorb_young`);
3. a new track, once validated, takes back the identity of a lost or recently
   deleted track that recognises it (:meth:`IdentityRecovery.recover_identities`).

Which detections may take part is the life-cycle's business
(:class:`~optrack.tracking.lifecycle.LifecyclePolicy`); the tracker calls these
steps in order and does the state updates.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from optrack.params import Params
from optrack.tracking.appearance import AppearanceModel
from optrack.tracking.association import assign
from optrack.tracking.lifecycle import Flag, TrackState
from optrack.types import Detection

__all__ = ["IdentityRecovery", "Reach"]

#: how far (m) a person can be from where they were last seen, for times unseen (s)
Reach = Callable[[np.ndarray], np.ndarray]


class IdentityRecovery:
    """Every track's colour classifier and the three recovery steps (``appearance`` params)."""

    def __init__(self, params: Params) -> None:
        self.params = params
        self.model = AppearanceModel(params)
        self.recovered = 0  # new tracks given a lost identity back
        self.matches = 0  # detections given to lost tracks by appearance alone

    # ---------------------------------------------------------------- features
    def features(self, detections: Sequence[Detection]) -> np.ndarray | None:
        """Features of the detections' colours, or None when none has colours. An occluded
        detection's colours are partly someone else's or something else's: none for it."""
        return self.model.features([[] if Flag.OCCLUDED.on(d) else d.histogram for d in detections])

    def note_birth(self, track: TrackState, feature: np.ndarray) -> None:
        """A new track keeps its first detection's features (when it has colours)."""
        if np.all(np.isfinite(feature)):
            track.features.append(feature)

    # ------------------------------------------------------------ association
    def lost(self, tracks: Sequence[TrackState], t: float, skip: set[int]) -> list[int]:
        """Indices of validated tracks lost long enough to give their identity away."""
        wait = self.params.sec_missing_before_recovery
        classifiers = self.model.classifiers
        return [
            i
            for i, tr in enumerate(tracks)
            if i not in skip
            and tr.validated
            and t - tr.confirmed >= wait
            and (c := classifiers.get(tr.id)) is not None
            and c.trained
        ]

    def rejected(
        self, tracks: Sequence[TrackState], t: float, features: np.ndarray
    ) -> np.ndarray | None:
        """(N, M) pairs of a track lost for long and a detection its classifier clearly
        rejects (confidence below ``-min_confidence``); None when no track is lost so long."""
        lost = self.lost(tracks, t, set())
        if not lost:
            return None
        out = np.zeros((len(tracks), len(features)), dtype=bool)
        looks = np.array([self.model.confidence(tracks[i].id, features) for i in lost])
        out[lost] = looks < -self.params.min_confidence
        return out

    def match_lost(
        self,
        tracks: Sequence[TrackState],
        t: float,
        positions: np.ndarray,
        features: np.ndarray,
        free: np.ndarray,
        associated: set[int],
        reach: Reach,
    ) -> list[tuple[TrackState, int]]:
        """Second association: the ``free`` detections (indices) against the classifiers of
        lost tracks (not among the ``associated`` indices) that recognise them, within
        reach of where they were last seen; (track, detection index) pairs."""
        candidates = self.lost(tracks, t, associated)
        if not free.size or not candidates:
            return []
        conf = np.array([self.model.confidence(tracks[i].id, features[free]) for i in candidates])
        last = np.array([tracks[i].last_seen() for i in candidates])
        lost_for = np.array([t - tracks[i].confirmed for i in candidates])
        distance = np.linalg.norm(positions[free][None, :, :] - last[:, None, :], axis=2)
        allowed = (conf >= self.params.min_confidence) & (distance <= reach(lost_for)[:, None])
        pairs = [(tracks[candidates[a]], int(free[b])) for a, b in assign(-conf, allowed)]
        self.matches += len(pairs)
        return pairs

    def absorb_young(
        self,
        tracks: list[TrackState],
        track: TrackState,
        position: np.ndarray,
        lost_since: float,
        radius: float,
    ) -> None:
        """A track started within ``radius`` of a recovered person while they were lost is
        that person (its first detections were too occluded to recognise): merge it into
        the identity."""
        for other in list(tracks):
            if other is track or other.born <= lost_since:
                continue
            ox, oy = other.last_seen()
            if math.hypot(ox - position[0], oy - position[1]) > radius:
                continue
            if other.features:
                score = np.mean(self.model.confidence(track.id, np.array(other.features)))
                if score < self.params.min_confidence:
                    continue
            tracks.remove(other)
            self.model.drop(other.id)
            track.detections += other.detections
            track.confident_detections += other.confident_detections

    def learn(
        self, t: float, pairs: Sequence[tuple[TrackState, int]], features: np.ndarray
    ) -> None:
        """Each associated, unoccluded detection teaches its track (and is kept for identity
        recovery among its first ones); the batch's others are negatives."""
        for track, j in pairs:
            if not np.all(np.isfinite(features[j])):
                continue  # occluded, or no histogram
            if len(track.features) < self.params.recovery_detections:
                track.features.append(features[j])
            self.model.learn(t, track.id, features[j], np.delete(features, j, axis=0))

    # ----------------------------------------------------------- identities
    def recover_identities(self, tracks: list[TrackState], t: float, reach: Reach) -> None:
        """Give a lost identity back to a new track its classifier recognises (Munaro 5.4),
        once the new track is validated: a false alarm (furniture) that happens to wear a
        lost person's colours must not become that person, shown at once. A track validated
        within its first ``recovery_detections`` detections is tried at each of them, one
        validated later (a weak run) once."""
        a = self.params
        for track in list(tracks):
            if track.recovery_done or track not in tracks or not track.validated:
                continue
            if not track.features:
                track.recovery_done = track.detections >= a.recovery_detections
                continue
            best = self._best_identity(tracks, track, reach)
            if best[1] is not None:
                self._give_identity(tracks, track, best[1], from_deleted=best[2])
                track.recovery_done = True
            else:
                track.recovery_done = track.detections >= a.recovery_detections

    def _best_identity(
        self, tracks: Sequence[TrackState], track: TrackState, reach: Reach
    ) -> tuple[float, int | None, bool]:
        """(score, identity, deleted) of the lost or deleted identity that recognises the
        track's first features best (at least ``min_confidence``), within reach of where
        the track started."""
        a = self.params
        F = np.array(track.features)
        best: tuple[float, int | None, bool] = (a.min_confidence, None, False)
        here = np.array(track.history[0][1:] if track.history else track.x[:2])
        for other in tracks:
            if other is track or not other.validated or other.confirmed >= track.born:
                continue
            if track.born - other.confirmed < a.sec_missing_before_recovery:
                continue
            c = self.model.classifiers.get(other.id)
            if c is None or not c.trained:
                continue
            last = np.array(other.last_seen())
            if np.linalg.norm(here - last) > reach(np.array([track.born - other.confirmed]))[0]:
                continue
            score = float(np.mean(self.model.confidence(other.id, F)))
            if score >= best[0]:
                best = (score, other.id, False)
        for tid, lx, ly, last_detection in self.model.lost_candidates():
            if last_detection >= track.born:
                continue
            if (
                np.hypot(here[0] - lx, here[1] - ly)
                > reach(np.array([track.born - last_detection]))[0]
            ):
                continue
            score = float(np.mean(self.model.lost_confidence(tid, F)))
            if score >= best[0]:
                best = (score, tid, True)
        return best

    def _give_identity(
        self, tracks: list[TrackState], track: TrackState, old_id: int, from_deleted: bool
    ) -> None:
        self.model.drop(track.id)
        if from_deleted:
            classifier = self.model.take_lost(old_id)
        else:
            old = next(tr for tr in tracks if tr.id == old_id)
            tracks.remove(old)
            classifier = self.model.classifiers.pop(old_id, None)
            track.born = min(track.born, old.born)
            track.detections += old.detections
        track.id = old_id
        if classifier is not None:
            self.model.adopt(old_id, classifier)
        self.recovered += 1

    # ------------------------------------------------------------------ ends
    def forget(self, track: TrackState, now: float) -> None:
        """A track was deleted after a life: keep its classifier for recovery a while."""
        x, y = track.last_seen()
        self.model.forget(track.id, x, y, track.confirmed, now)

    def drop(self, track: TrackState) -> None:
        """A track ended without being worth remembering (a fake)."""
        self.model.drop(track.id)
