"""Track life-cycle (Munaro 2012 section 5.4) with OpenPTrack's multi-camera defaults."""

from __future__ import annotations

import numpy as np
import pytest

from optrack.tracking import TRACKING_PARAMS, Tracker
from optrack.tracking.lifecycle import (
    EXPLAINED_WEAK_DETECTIONS,
    REVIVAL_FLAGS,
    Flag,
    LifecyclePolicy,
)
from optrack.types import Detection, DetectionBatch, TrackStatus

RATE = 30.0


def _batch(
    t: float, *xs: float, confidence: float = 1.0, sensor: str = "a", **flags: bool
) -> DetectionBatch:
    people = [Detection(x=x, y=0.0, z=0.9, height=1.7, confidence=confidence, **flags) for x in xs]
    return DetectionBatch(sensor_id=sensor, stamp=t, detections=people)


def _run(tracker: Tracker, start: float, stop: float, *xs: float, **kw) -> None:
    k = 0
    while start + k / RATE < stop - 1e-9:
        tracker.update(_batch(start + k / RATE, *xs, **kw))
        k += 1


def test_schema_holds_openptracks_multi_camera_defaults() -> None:
    p = TRACKING_PARAMS.create()
    assert (p.gate_probability, p.acceleration_variance, p.position_variance_weight) == (
        0.99,
        100.0,
        30.0,
    )
    assert (p.detector_weight, p.motion_weight) == (-0.25, 0.25)
    assert (p.sec_before_old, p.sec_before_fake, p.sec_remain_new) == (8.0, 2.4, 1.2)
    assert (p.detections_to_validate, p.max_detection_delay) == (3, 2.0)


def test_an_unvalidated_track_dies_after_sec_before_fake() -> None:
    # detections at 0.0 count for neither validation (confident or weak)
    tracker = Tracker(
        TRACKING_PARAMS.create(
            {"min_confidence_initialization": 0.5, "min_confidence_weak_initialization": 0.5}
        )
    )
    tracker.update(_batch(0.0, 1.0))  # born (confident) ...
    tracker.update(_batch(1 / RATE, 1.0, confidence=0.0))  # ... then only weak detections
    _run(tracker, 2 / RATE, 2.35, 1.0, confidence=0.0)
    assert [tr.validated for tr in tracker.tracks] == [False]
    assert tracker.output().tracks == []  # never published
    _run(tracker, 2.35, 2.45, 1.0, confidence=0.0)
    assert tracker.tracks == []


def test_an_unvalidated_track_that_goes_missing_dies_at_once() -> None:
    """A person just found is seen in every frame; a flickering false alarm is not."""
    tracker = Tracker()
    tracker.update(_batch(0.0, 1.0))
    _run(tracker, 0.1, 0.19)  # empty batches
    assert len(tracker.tracks) == 1
    _run(tracker, 0.19, 0.25)
    assert tracker.tracks == []


def test_a_stray_detection_does_not_keep_a_lost_track_alive() -> None:
    tracker = Tracker()
    _run(tracker, 0.0, 1.0, 1.0)
    (track,) = tracker.tracks
    for k in range(2, 9):  # lost; every second a single detection where it could be
        _run(tracker, k - 1 + 0.04, k)
        tracker.update(_batch(float(k), 1.0 + 0.3 * k))
        assert tracker.output().tracks[0].status == "missing"
    _run(tracker, 8.04, 8.95)
    assert tracker.tracks == [track]
    _run(tracker, 8.97, 9.02)
    assert tracker.tracks == []  # sec_before_old after the last confirmed sighting


def test_a_track_is_validated_by_detections_to_validate_confident_detections() -> None:
    tracker = Tracker(TRACKING_PARAMS.create({"min_confidence_initialization": 0.5}))
    tracker.update(_batch(0.0, 1.0))
    tracker.update(_batch(1 / RATE, 1.0))
    assert tracker.output().tracks == []
    tracker.update(_batch(2 / RATE, 1.0))
    assert [t.id for t in tracker.output().tracks] == [1]


def test_new_becomes_normal_after_sec_remain_new_then_missing_then_deleted_after_sec_before_old() -> (
    None
):
    tracker = Tracker()
    _run(tracker, 0.0, 1.0, 1.0)
    assert tracker.tracks[0].status is TrackStatus.NEW
    _run(tracker, 1.0, 1.5, 1.0)
    assert tracker.tracks[0].status is TrackStatus.NORMAL
    last = tracker.tracks[0].last_detection
    _run(tracker, 1.5, 1.5 + 0.3)  # nobody
    assert tracker.tracks[0].status is TrackStatus.MISSING
    assert tracker.output().tracks[0].status == "missing"
    _run(tracker, 1.8, last + 7.9)
    assert len(tracker.tracks) == 1
    _run(tracker, last + 7.9, last + 8.1)
    assert tracker.tracks == []


def test_a_missing_track_becomes_normal_again_when_detected() -> None:
    tracker = Tracker()
    _run(tracker, 0.0, 2.0, 1.0)
    _run(tracker, 2.0, 2.5)
    assert tracker.tracks[0].status is TrackStatus.MISSING
    _run(tracker, 2.5, 2.6, 1.0)
    assert tracker.tracks[0].status is TrackStatus.NORMAL
    assert tracker.tracks[0].id == 1


WEAK = {"min_confidence_initialization": 0.5, "min_confidence_weak_initialization": 0.0}


def test_a_detection_below_the_weak_threshold_starts_no_track() -> None:
    tracker = Tracker(TRACKING_PARAMS.create(WEAK))
    _run(tracker, 0.0, 1.0, 1.0, confidence=-0.2)
    assert tracker.tracks == []


def test_a_weak_but_steady_detection_is_published_after_weak_detections_to_validate_in_a_row() -> (
    None
):
    """A person half hidden behind furniture: weak detections, but in every frame."""
    tracker = Tracker(TRACKING_PARAMS.create(WEAK))
    needed = tracker.params.weak_detections_to_validate
    _run(tracker, 0.0, (needed - 1) / RATE, 1.0, confidence=0.2)
    assert len(tracker.tracks) == 1
    assert tracker.output().tracks == []
    tracker.update(_batch((needed - 1) / RATE, 1.0, confidence=0.2))
    assert [t.id for t in tracker.output().tracks] == [1]


def test_a_flickering_weak_detection_is_never_published() -> None:
    """A false alarm seen in every other frame of its sensor never makes a run long enough."""
    tracker = Tracker(TRACKING_PARAMS.create(WEAK))
    for k in range(60):
        tracker.update(_batch(k / RATE, *([1.0] if k % 2 == 0 else []), confidence=0.2))
        assert tracker.output().tracks == []
    assert len(tracker.tracks) == 1  # alive (never unseen for sec_before_missing), unpublished


@pytest.mark.parametrize(
    ("explained", "flag"),
    [
        ("out_of_view", "out_of_view"),
        ("out_of_view_or_occluded", "out_of_view"),
        ("out_of_view_or_occluded", "occluded"),
    ],
)
def test_a_weak_detection_flagged_partly_hidden_is_published_after_detections_to_validate_in_a_row(
    explained: str, flag: str
) -> None:
    """The detector says why the margin is low (the image's edge, or something in front):
    such weak detections in a row validate as fast as confident ones."""
    tracker = Tracker(TRACKING_PARAMS.create({**WEAK, "explained_weak_detections": explained}))
    needed = tracker.params.detections_to_validate
    assert needed < tracker.params.weak_detections_to_validate
    _run(tracker, 0.0, (needed - 1) / RATE, 1.0, confidence=0.2, **{flag: True})
    assert tracker.output().tracks == []
    tracker.update(_batch((needed - 1) / RATE, 1.0, confidence=0.2, **{flag: True}))
    assert [t.id for t in tracker.output().tracks] == [1]


@pytest.mark.parametrize(
    ("explained", "flag"),
    [("out_of_view", "occluded"), ("none", "out_of_view"), ("none", "occluded")],
)
def test_a_weak_detection_whose_flag_is_not_trusted_needs_weak_detections_to_validate(
    explained: str, flag: str
) -> None:
    """By default 'occluded' explains nothing: furniture behind furniture is flagged too."""
    assert TRACKING_PARAMS.create().explained_weak_detections == "out_of_view"
    tracker = Tracker(TRACKING_PARAMS.create({**WEAK, "explained_weak_detections": explained}))
    needed = tracker.params.weak_detections_to_validate
    _run(tracker, 0.0, (needed - 1) / RATE, 1.0, confidence=0.2, **{flag: True})
    assert tracker.output().tracks == []
    tracker.update(_batch((needed - 1) / RATE, 1.0, confidence=0.2, **{flag: True}))
    assert [t.id for t in tracker.output().tracks] == [1]


def test_a_flickering_weak_detection_flagged_partly_hidden_is_never_published() -> None:
    """A flagged false alarm that flickers makes no run, even with both flags trusted."""
    tracker = Tracker(
        TRACKING_PARAMS.create({**WEAK, "explained_weak_detections": "out_of_view_or_occluded"})
    )
    for k in range(60):
        people = [1.0] if k % 2 == 0 else []
        flags = {"occluded": True} if k % 4 == 0 else {"out_of_view": True}
        tracker.update(_batch(k / RATE, *people, confidence=0.2, **flags))
        assert tracker.output().tracks == []


def test_a_run_of_weak_then_partly_hidden_detections_adds_up() -> None:
    """Each detection in a run counts its share: a weak one 1/weak_detections_to_validate,
    a flagged one 1/detections_to_validate (7 weak + 1 flagged = 0.7 + 0.33 >= 1)."""
    tracker = Tracker(TRACKING_PARAMS.create(WEAK))
    p = tracker.params
    assert (p.detections_to_validate, p.weak_detections_to_validate) == (3, 10)
    _run(tracker, 0.0, 7 / RATE, 1.0, confidence=0.2)
    assert tracker.output().tracks == []
    tracker.update(_batch(7 / RATE, 1.0, confidence=0.2, out_of_view=True))
    assert [t.id for t in tracker.output().tracks] == [1]


def test_frames_of_another_sensor_do_not_break_a_sensors_run() -> None:
    """Only a frame of a sensor that saw the track and missed it starts its run over."""
    tracker = Tracker(TRACKING_PARAMS.create(WEAK))
    needed = tracker.params.weak_detections_to_validate
    for k in range(needed):
        tracker.update(_batch(k / RATE, 1.0, confidence=0.2, sensor="a"))
        tracker.update(_batch(k / RATE + 0.001, sensor="b"))  # b does not see there
    assert [t.id for t in tracker.output().tracks] == [1]


def test_detections_below_min_confidence_detections_are_ignored() -> None:
    tracker = Tracker(TRACKING_PARAMS.create({"min_confidence_detections": -1.0}))
    _run(tracker, 0.0, 1.0, 1.0)
    _run(tracker, 1.0, 1.5, 1.0, confidence=-1.5)
    assert tracker.tracks[0].last_detection == pytest.approx(1.0 - 1 / RATE)


def test_a_weak_second_detection_beside_a_tracked_person_starts_no_track() -> None:
    """A split silhouette or a second sensor's weak view of someone tracked is no new person."""
    tracker = Tracker(TRACKING_PARAMS.create(WEAK))
    _run(tracker, 0.0, 0.2, 1.0)  # tracked first
    for k in range(6, 45):
        people = [
            Detection(x=1.0, y=0.0, z=0.9, height=1.7, confidence=1.0),
            Detection(x=1.15, y=0.0, z=0.9, height=1.7, confidence=0.2),
        ]
        tracker.update(DetectionBatch(sensor_id="a", stamp=k / RATE, detections=people))
    assert [t.id for t in tracker.output().tracks] == [1]
    assert len(tracker.tracks) == 1


HOLD = {"out_of_view_hold": "on"}


@pytest.mark.parametrize(("sensors", "mode", "held"), [(1, None, False), (3, "on", True)])
def test_the_out_of_view_hold_is_off_by_default_and_switchable(
    sensors: int, mode: str | None, held: bool
) -> None:
    p = TRACKING_PARAMS.create({"out_of_view_hold": mode} if mode else {})
    assert p.sec_before_missing_out_of_view == 0.6 and p.sec_before_missing == 0.2
    tracker = Tracker(p, sensors=sensors)
    assert tracker.out_of_view_hold is held
    _run(tracker, 0.0, 0.7, 1.0)
    _run(tracker, 0.7, 1.0 + 1e-6, 1.0, out_of_view=True)
    expected = TrackStatus.NEW if held else TrackStatus.MISSING
    assert _status_after(tracker, 1.0, 0.25) is expected


def _status_after(tracker: Tracker, last: float, unseen: float) -> TrackStatus:
    _run(tracker, last + 1 / RATE, last + unseen)  # nobody
    return tracker.tracks[0].status


@pytest.mark.parametrize("flagged", [False, True])
def test_a_track_lost_at_the_images_edge_goes_missing_after_sec_before_missing_out_of_view(
    flagged: bool,
) -> None:
    """The detector gives up on a person cut by the image's edge while much of them is
    still in the image: such a track stays unmissing (held in the output) for longer."""
    tracker = Tracker(TRACKING_PARAMS.create(HOLD))
    _run(tracker, 0.0, 0.7, 1.0)
    _run(tracker, 0.7, 1.0 + 1e-6, 1.0, out_of_view=flagged)  # the last 0.3 s
    assert _status_after(tracker, 1.0, 0.3) is (TrackStatus.NEW if flagged else TrackStatus.MISSING)
    assert _status_after(tracker, 1.3, 0.35) is TrackStatus.MISSING
    # association and deletion are those of any track: it is deleted sec_before_old after
    _run(tracker, 1.7, 9.1)
    assert tracker.tracks == []


def test_only_a_track_seen_cut_by_the_edge_to_the_end_is_held() -> None:
    tracker = Tracker(TRACKING_PARAMS.create(HOLD))
    _run(tracker, 0.0, 0.5, 1.0, out_of_view=True)
    _run(tracker, 0.5, 1.0, 1.0)  # back in full view, then lost
    assert _status_after(tracker, 1.0 - 1 / RATE, 0.3) is TrackStatus.MISSING


def test_a_track_another_sensor_saw_in_full_at_the_end_is_not_held() -> None:
    """Sensor a loses the person at its image's edge while sensor b still sees them in
    full (and then loses them for another reason): no hold."""
    tracker = Tracker(TRACKING_PARAMS.create(HOLD))
    _run(tracker, 0.0, 1.0, 1.0)
    tracker.update(_batch(1.0, 1.0, sensor="b"))
    tracker.update(_batch(1.01, 1.0, out_of_view=True))
    assert _status_after(tracker, 1.01, 0.3) is TrackStatus.MISSING


def test_an_unvalidated_track_lost_at_the_images_edge_still_dies_at_once() -> None:
    tracker = Tracker(TRACKING_PARAMS.create(HOLD))
    tracker.update(_batch(0.0, 1.0, out_of_view=True))
    _run(tracker, 0.1, 0.25)  # empty batches
    assert tracker.tracks == []


@pytest.mark.parametrize(
    ("window", "gap", "flags", "revived"),
    [
        (0.5, 0.3, {"occluded": True}, True),  # steps out from behind someone
        (0.5, 0.3, {"out_of_view": True}, True),  # steps back in at the image's edge
        (0.5, 0.3, {}, False),  # weak and unexplained: could be furniture
        (0.5, 0.8, {"occluded": True}, False),  # lost too long ago
        (0.0, 0.3, {"occluded": True}, False),  # revival switched off
    ],
)
def test_a_weak_partly_hidden_detection_revives_a_track_lost_moments_ago(
    window: float, gap: float, flags: dict[str, bool], revived: bool
) -> None:
    """Someone hidden for a moment behind someone else is detected weakly when they step
    out; the detector flags why, and the track lost moments ago takes them back."""
    tracker = Tracker(TRACKING_PARAMS.create({"sec_weak_revival": window}))
    weak = tracker.params.min_confidence_initialization - 0.7
    assert weak >= tracker.params.min_confidence_detections
    _run(tracker, 0.0, 1.0, 1.0)
    (track,) = tracker.tracks
    _run(tracker, 1.0, 1.0 + gap)  # hidden: nothing detected
    assert tracker.output().tracks[0].status == "missing"
    _run(tracker, 1.0 + gap, 1.2 + gap, 1.0, confidence=weak, **flags)
    assert tracker.tracks == [track]  # no second track either way
    status = tracker.output().tracks[0].status
    assert (status != "missing") is revived
    assert (tracker.tracks[0].last_detection > 1.0 + gap) is revived


def test_a_weak_partly_hidden_detection_away_from_the_prediction_revives_nothing() -> None:
    """Only where the lost track predicts the person (within min_reach)."""
    tracker = Tracker()
    weak = tracker.params.min_confidence_initialization - 0.7
    _run(tracker, 0.0, 1.0, 1.0)
    _run(tracker, 1.0, 1.3)
    far = 1.0 + tracker.params.min_reach + 0.2
    _run(tracker, 1.3, 1.5, far, confidence=weak, occluded=True)
    assert tracker.tracks[0].last_detection < 1.0
    assert tracker.output().tracks[0].status == "missing"


def _detection(confidence: float, **flags: bool) -> Detection:
    return Detection(x=0.0, y=0.0, z=0.9, height=1.7, confidence=confidence, **flags)


def test_the_policy_is_read_from_the_parameters_and_follows_a_live_change() -> None:
    tracker = Tracker()
    policy = tracker.policy
    assert policy == LifecyclePolicy.from_params(TRACKING_PARAMS.create())
    assert (policy.min_confidence, policy.weak_floor) == (-1.5, -3.5)
    assert policy.explaining_flags == {Flag.OUT_OF_VIEW}
    assert (policy.out_of_view_hold, policy.revival_radius) == (False, 0.5)
    # a weak run: a confident or explained detection weighs 1/3, a weak one 1/10
    assert (policy.strong_weight, policy.weak_weight, policy.run_to_validate) == (10, 3, 30)
    tracker.params.update({"explained_weak_detections": "none", "out_of_view_hold": "on"})
    tracker.update(_batch(0.0))
    assert tracker.policy.explaining_flags == frozenset()
    assert tracker.policy.out_of_view_hold


def test_the_detectors_flags_are_named_and_each_setting_says_which_explain_weakness() -> None:
    assert {flag.value for flag in Flag} <= set(Detection.__struct_fields__)
    assert TRACKING_PARAMS["explained_weak_detections"].choices == tuple(EXPLAINED_WEAK_DETECTIONS)
    assert REVIVAL_FLAGS == {Flag.OCCLUDED, Flag.OUT_OF_VIEW}
    both = LifecyclePolicy.from_params(
        TRACKING_PARAMS.create({"explained_weak_detections": "out_of_view_or_occluded"})
    )
    none = LifecyclePolicy.from_params(
        TRACKING_PARAMS.create({"explained_weak_detections": "none"})
    )
    default = Tracker().policy
    for flags, by_default, by_both in (
        ({"out_of_view": True}, True, True),
        ({"occluded": True}, False, True),
        ({}, False, False),
    ):
        weak = _detection(-2.5, **flags)
        assert default.explained(weak) is by_default
        assert both.explained(weak) is by_both
        assert not none.explained(weak)
        # appearance gives a lost track a weak detection only when its flags explain it
        assert default.may_be_recognised(weak) is by_default
    assert default.may_be_recognised(_detection(0.0))


@pytest.mark.parametrize(
    ("confidence", "near_a_track", "starts"),
    [
        (0.0, False, True),  # confident
        (0.0, True, True),  # confident, even beside a track (two people close together)
        (-2.5, False, True),  # weak, nobody tracked there
        (-2.5, True, False),  # weak, a track could take it: no new person
        (-3.6, False, False),  # below min_confidence_weak_initialization
    ],
)
def test_the_policy_says_which_detection_left_over_starts_a_track(
    confidence: float, near_a_track: bool, starts: bool
) -> None:
    assert Tracker().policy.may_start(_detection(confidence), near_a_track) is starts


def test_the_policy_bars_weak_detections_from_missing_tracks_but_for_a_weak_revival() -> None:
    from optrack.tracking.association import Candidates

    tracker = Tracker()
    _run(tracker, 0.0, 1.0, 1.0, 3.0)  # two people; the one at 3 m is lost from 1.0 s
    _run(tracker, 1.0, 1.3, 1.0)
    near, lost = tracker.tracks
    detections = [
        _detection(0.0),  # confident: bars nothing
        _detection(-2.5),  # weak, unflagged: cannot revive
        _detection(-2.5, occluded=True),  # weak, flagged, where the lost track predicts
    ]
    positions = np.array([[3.0, 0.0], [3.0, 0.0], [3.1, 0.0]])
    candidates = Candidates(
        t=1.3,
        tracks=tracker.tracks,
        detections=detections,
        positions=positions,
        confidence=np.array([d.confidence for d in detections]),
        predicted=np.array([near.x, lost.x]),
        d2=np.zeros((2, 3)),
        logdet=np.zeros((2, 3)),
        last_seen=np.array([near.x[:2], lost.x[:2]]),
        unseen=np.array([0.0, 0.3]),
        chi_square=tracker.gate,
        settings=tracker.p,
    )
    barred = tracker.policy.revival_barred(candidates)
    assert barred.tolist() == [[False, False, False], [False, True, False]]
    off = LifecyclePolicy.from_params(TRACKING_PARAMS.create({"sec_weak_revival": 0.0}))
    assert off.revival_barred(candidates).tolist() == [[False, False, False], [False, True, True]]
