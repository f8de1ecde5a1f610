"""Parameters of the central tracker, its appearance model and its output smoothing.

Defaults are OpenPTrack's multi-camera tracker settings
(``tracking/conf/tracker_multicamera.yaml``) where OpenPTrack has the value;
the others are named after what they do and documented in docs/tracking.md.
"""

from __future__ import annotations

from optrack.params import Param, Schema, register
from optrack.tracking.lifecycle import EXPLAINED_WEAK_DETECTIONS

__all__ = ["APPEARANCE_PARAMS", "SMOOTHING_PARAMS", "TRACKING_PARAMS"]

TRACKING_PARAMS = register(
    Schema(
        "tracking",
        [
            # ---- motion model (UKF, constant velocity)
            Param(
                "acceleration_variance",
                100.0,
                min=0.01,
                max=10000.0,
                step=1.0,
                unit="m^2/s^4",
                help="Variance of the white-noise acceleration of a walking person, per frame "
                "of acceleration_rate (OpenPTrack's value).",
            ),
            Param(
                "acceleration_rate",
                30.0,
                min=1.0,
                max=300.0,
                step=1.0,
                unit="Hz",
                help="Frame rate at which acceleration_variance is defined; the process noise's "
                "spectral density is acceleration_variance / acceleration_rate.",
            ),
            Param(
                "position_variance_weight",
                30.0,
                min=0.1,
                max=1000.0,
                step=1.0,
                help="Detection position variance in units of the voxel quantisation variance "
                "voxel_size^2 / 12 (the detector's voxel_size, which each detection batch carries).",
            ),
            Param(
                "depth_error_coefficient",
                0.0015,
                min=0.0,
                max=0.05,
                step=0.0005,
                unit="1/m",
                help="Depth error of the sensor: standard deviation k * distance^2, added to the "
                "position variance of each detection.",
            ),
            Param(
                "velocity_baseline",
                0.2,
                min=0.01,
                max=2.0,
                step=0.01,
                unit="s",
                help="A detection's velocity is measured against the track's position at least "
                "this long before it (paper eq. 5-6).",
            ),
            Param(
                "initial_velocity_variance",
                1.0,
                min=0.01,
                max=100.0,
                step=0.1,
                unit="m^2/s^2",
                help="Velocity variance of a newborn track.",
            ),
            Param("ukf_alpha", 1.0, min=1e-4, max=1.0, help="UKF sigma-point spread (Merwe)."),
            Param("ukf_beta", 2.0, min=0.0, max=10.0, help="UKF prior knowledge of the state."),
            Param("ukf_kappa", 0.0, min=-3.0, max=10.0, help="UKF secondary scaling."),
            # ---- association
            Param(
                "gate_probability",
                0.99,
                min=0.5,
                max=0.999999,
                step=0.001,
                help="Probability mass of the association gate; the gate is the chi-square "
                "quantile of this probability with 4 degrees of freedom.",
            ),
            Param(
                "max_speed",
                2.5,
                min=0.1,
                max=10.0,
                step=0.1,
                unit="m/s",
                help="A track can take a detection at most min_reach plus this speed times the "
                "time since it was last detected from where it was last detected.",
            ),
            Param(
                "min_reach",
                0.5,
                min=0.05,
                max=10.0,
                step=0.05,
                unit="m",
                help="Reach of a track just detected (noise and calibration differences between "
                "sensors).",
            ),
            Param(
                "motion_weight",
                0.25,
                min=0.0,
                max=10.0,
                step=0.05,
                help="Weight of the motion term (Mahalanobis distance) in the association cost.",
            ),
            Param(
                "detector_weight",
                -0.25,
                min=-10.0,
                max=10.0,
                step=0.05,
                help="Weight of the detection confidence in the association cost (negative: "
                "confident detections are cheaper).",
            ),
            # ---- life-cycle (Munaro 2012 section 5.4)
            Param(
                "min_confidence_detections",
                -10.0,
                min=-100.0,
                max=100.0,
                step=0.1,
                help="Detections less confident than this are ignored by the tracker (the default "
                "keeps all the detector sends).",
            ),
            Param(
                "min_confidence_initialization",
                -1.5,
                min=-100.0,
                max=100.0,
                step=0.1,
                help="A detection left over by association starts a track only with at least "
                "this confidence (HOG margin; the detector sends from about -1.75).",
            ),
            Param(
                "min_confidence_weak_initialization",
                -3.5,
                min=-100.0,
                max=100.0,
                step=0.1,
                help="A detection left over by association that is below "
                "min_confidence_initialization but at least this confident starts a track that "
                "only weak_detections_to_validate detections in a row validate (a person half "
                "hidden behind furniture is seen weakly but steadily; a false alarm flickers). "
                "Just below the detectors' own thresholds (Kinect -3.0, SR4500 -3.25).",
            ),
            Param(
                "detections_to_validate",
                3,
                min=1,
                max=100,
                step=1,
                help="Detections with at least min_confidence_initialization a new track needs "
                "before it is validated (published).",
            ),
            Param(
                "weak_detections_to_validate",
                10,
                min=1,
                max=1000,
                step=1,
                help="A track needs this many detections in a row (no frame of a sensor that saw "
                "it missing it) to be validated on weak detections alone.",
            ),
            Param(
                "explained_weak_detections",
                "out_of_view",
                choices=tuple(EXPLAINED_WEAK_DETECTIONS),
                help="Weak detections whose low HOG margin the detector's flags explain (part of "
                "the person outside the image; or also behind something nearer) weigh as "
                "confident ones in a run of detections in a row. 'occluded' is off by default: "
                "the detector also flags furniture behind furniture occluded, in runs.",
            ),
            Param(
                "sec_before_fake",
                2.4,
                min=0.1,
                max=60.0,
                step=0.1,
                unit="s",
                help="A track not validated this long after its birth is deleted as fake.",
            ),
            Param(
                "sec_remain_new",
                1.2,
                min=0.0,
                max=60.0,
                step=0.1,
                unit="s",
                help="A track stays NEW this long after its birth, then becomes NORMAL.",
            ),
            Param(
                "sec_before_missing",
                0.2,
                min=0.0,
                max=10.0,
                step=0.05,
                unit="s",
                help="A track no sensor has detected for this long is MISSING.",
            ),
            Param(
                "sec_weak_revival",
                0.5,
                min=0.0,
                max=10.0,
                step=0.05,
                unit="s",
                help="A track lost for at most this long may be taken back by a detection too "
                "weak to start a track, if the detector flags it partly hidden (behind "
                "something, or at the image's edge) and it lies within min_reach of where the "
                "track predicts the person: someone stepping out from behind someone else is "
                "detected weakly at first. 0 lets no weak detection revive a lost track.",
            ),
            Param(
                "sec_before_missing_out_of_view",
                0.6,
                min=0.0,
                max=10.0,
                step=0.05,
                unit="s",
                help="Where the out-of-view hold applies, a validated track lost at the image's "
                "edge (every detection of its last sec_before_missing flagged out_of_view) is "
                "MISSING only after this long unseen (never sooner than sec_before_missing), "
                "so the output holds it as long as OpenPTrack's output holds everyone.",
            ),
            Param(
                "out_of_view_hold",
                "off",
                choices=("off", "on"),
                help="Hold a track lost at the image's edge for sec_before_missing_out_of_view. "
                "Off by default: it helps where people step back into a sensor's view, but "
                "shows people who walked out of view for good where they are not, and over the "
                "measured recordings, one sensor or several, it costs more than it gains "
                "(docs/tracking.md).",
            ),
            Param(
                "sec_before_old",
                8.0,
                min=0.1,
                max=600.0,
                step=0.5,
                unit="s",
                help="A validated track no sensor has detected for this long is deleted.",
            ),
            # ---- asynchronous sensors
            Param(
                "max_detection_delay",
                2.0,
                min=0.0,
                max=60.0,
                step=0.1,
                unit="s",
                help="Detection batches older than this (behind the newest one) are dropped and "
                "counted.",
            ),
            Param(
                "sensor_timeout",
                2.0,
                min=0.1,
                max=600.0,
                step=0.1,
                unit="s",
                help="A sensor silent this long raises a warning in the tracker status.",
            ),
            Param(
                "appearance",
                "auto",
                choices=("auto", "on", "off"),
                help="Appearance (colour) recovery of identities: auto is on for one sensor and "
                "off for networks, as OpenPTrack.",
            ),
        ],
        help="Central tracker: motion model, association, track life-cycle.",
    )
)

APPEARANCE_PARAMS = register(
    Schema(
        "appearance",
        [
            Param(
                "histogram_shape",
                "16x4",
                help="Bins per axis of a detection's colour histogram (the detector's hue x "
                "saturation); a histogram of another length is taken as one axis.",
            ),
            Param(
                "features",
                100,
                min=4,
                max=2000,
                step=1,
                help="Weak-learner pool: random boxes in the colour histogram.",
            ),
            Param(
                "selectors",
                20,
                min=1,
                max=200,
                step=1,
                help="Selectors (weak learners combined) of each track's boosted classifier.",
            ),
            Param(
                "min_box_bins",
                2,
                min=1,
                max=64,
                step=1,
                help="Smallest side of a random box, in histogram bins per channel.",
            ),
            Param(
                "min_feature_std",
                0.01,
                min=1e-6,
                max=1.0,
                help="Floor of a weak learner's feature standard deviation (histogram mass).",
            ),
            Param(
                "learning_rate",
                0.05,
                min=0.001,
                max=1.0,
                step=0.005,
                help="Forgetting rate of the weak learners' feature statistics.",
            ),
            Param(
                "update_interval",
                0.1,
                min=0.0,
                max=10.0,
                step=0.05,
                unit="s",
                help="A track's classifier learns at most once per this interval.",
            ),
            Param(
                "max_negatives",
                4,
                min=1,
                max=100,
                step=1,
                help="Negative examples (other people) per learning step.",
            ),
            Param(
                "generic_negatives",
                2,
                min=0,
                max=100,
                step=1,
                help="Random colour histograms added as negatives to each learning step, so a "
                "classifier rejects colours it has never seen, not only the people around.",
            ),
            Param(
                "generic_concentration",
                0.05,
                min=0.001,
                max=10.0,
                help="Dirichlet concentration of the random negatives (small: few colours each).",
            ),
            Param(
                "negative_memory",
                10.0,
                min=0.1,
                max=600.0,
                step=0.5,
                unit="s",
                help="Histograms of other people are kept this long as negative examples.",
            ),
            Param(
                "min_confidence",
                0.5,
                min=-1.0,
                max=1.0,
                step=0.05,
                help="Classifier confidence (-1..1) needed to give a detection or a new track a "
                "lost identity.",
            ),
            Param(
                "min_samples",
                5,
                min=1,
                max=1000,
                step=1,
                help="Positive examples a classifier needs before it is trusted.",
            ),
            Param(
                "sec_missing_before_recovery",
                0.5,
                min=0.0,
                max=60.0,
                step=0.1,
                unit="s",
                help="Only tracks missing at least this long give their identity away.",
            ),
            Param(
                "recovery_detections",
                5,
                min=1,
                max=100,
                step=1,
                help="A new track can take a lost identity within its first this many detections.",
            ),
            Param(
                "memory",
                20.0,
                min=0.0,
                max=600.0,
                step=1.0,
                unit="s",
                help="A deleted track's identity can be recovered this long after deletion.",
            ),
            Param("seed", 0, min=0, max=2**31 - 1, step=1, help="Seed of the random boxes."),
        ],
        help="On-line boosted colour classifiers that recover identities (Munaro 2012).",
    )
)

SMOOTHING_PARAMS = register(
    Schema(
        "smoothing",
        [
            Param(
                "window",
                5,
                min=1,
                max=100,
                step=1,
                help="Moving-average window over each track's positions.",
            ),
            Param(
                "rate",
                30.0,
                min=1.0,
                max=240.0,
                step=1.0,
                unit="Hz",
                help="Rate at which smoothed tracks are republished.",
            ),
            Param(
                "drop_after",
                0.6,
                min=0.0,
                max=60.0,
                step=0.1,
                unit="s",
                help="Tracks unseen this long are left out of the output.",
            ),
        ],
        help="Output smoothing and republishing (OpenPTrack's moving-average node).",
    )
)
