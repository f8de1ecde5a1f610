"""Parameters of the people detector, with OpenPTrack's defaults per sensor model.

The schema's defaults are OpenPTrack's generic detector configuration
(``detection/conf/ground_based_people_detector.yaml``); :data:`SENSOR_MODELS`
holds the per-model values of OpenPTrack's ``*_kinect1``, ``*_kinect2`` and
``*_sr`` files, and ``pcl``: the settings of PCL's own unit test of its
``GroundBasedPeopleDetectionApp`` (the reference for a bare ``.pcd``).
:data:`PRESETS` are named overlays on top of a sensor model (``children``).

Confidences are scores of OpenCV's default HOG people detector (Dalal and
Triggs' linear SVM): a signed margin, 0 at the SVM's own decision boundary.
OpenPTrack's thresholds (-1.75, and -2.0 for the SR4500) were set for PCL's
own SVM and HOG, whose scores run higher than OpenCV's on the same people,
so optrack's are -3.0 and -3.25 (same 0.25 step for infrared): measured on
simulated recordings they keep recall above 0.9 where -1.75 loses a fifth
of the people, and on PCL's real frames they still refuse every non-person
(docs/detection.md).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from optrack.params import Param, ParamError, Params, Schema, register

__all__ = [
    "DETECTION_PARAMS",
    "PRESETS",
    "SENSOR_MODELS",
    "check_config_section",
    "detection_params",
]

DETECTION_PARAMS = register(
    Schema(
        "detection",
        [
            # ----------------------------------------------------- preprocessing
            Param(
                "max_distance",
                15.0,
                min=0.5,
                max=50.0,
                step=0.5,
                unit="m",
                help="Points farther from the sensor than this are ignored.",
            ),
            Param(
                "sampling_factor",
                4,
                min=1,
                max=8,
                step=1,
                help="Keep every n-th pixel in rows and columns before the voxel grid.",
            ),
            Param(
                "voxel_size",
                0.06,
                min=0.01,
                max=0.2,
                step=0.01,
                unit="m",
                help="Voxel grid leaf size (smaller: slower and more precise).",
            ),
            Param(
                "confidence_threshold",
                0,
                min=0,
                max=65535,
                step=1,
                help="Time-of-flight sensors: drop pixels whose depth confidence is below this "
                "(SR4500: 200 on its 8-bit confidence image; 0 keeps all).",
            ),
            Param(
                "apply_denoising",
                False,
                help="Remove statistical outliers (Open3D) before the voxel grid.",
            ),
            Param(
                "mean_k_denoising",
                5,
                min=2,
                max=50,
                step=1,
                help="Denoising: neighbours considered for each point's mean distance.",
            ),
            Param(
                "std_dev_denoising",
                0.3,
                min=0.01,
                max=5.0,
                step=0.05,
                help="Denoising: drop points whose mean distance exceeds the average by this many "
                "standard deviations (lower: stronger).",
            ),
            Param(
                "valid_points_threshold",
                0.3,
                min=0.0,
                max=1.0,
                step=0.05,
                help="A frame is used to estimate the ground only if at least this fraction of "
                "its pixels has depth.",
            ),
            # -------------------------------------------------------- ground plane
            Param(
                "ground_from_calibration",
                True,
                help="When the sensor is calibrated, combine the calibration's floor with the "
                "cloud's (OpenPTrack's rule).",
            ),
            Param(
                "calibration_ground_tolerance",
                0.2,
                min=0.01,
                max=2.0,
                step=0.01,
                unit="m",
                help="Keep the calibration's floor when the cloud's floor is missing or its "
                "camera height differs by more than this.",
            ),
            Param(
                "read_ground_from_file",
                False,
                help="Start from the floor saved for this sensor, when there is one.",
            ),
            Param(
                "lock_ground",
                False,
                help="Do not refit the floor to each frame.",
            ),
            Param(
                "ground_inlier_distance",
                0.06,
                min=0.005,
                max=0.5,
                step=0.005,
                unit="m",
                help="Points this close to the floor are floor: removed, and used to refit it.",
            ),
            Param(
                "ground_update_min_points",
                300,
                min=3,
                max=100000,
                step=10,
                help="Refit the floor only with at least this many floor voxels at 0.06 m and "
                "sampling 1 (scaled as 0.06/voxel_size/sampling_factor^2, as OpenPTrack).",
            ),
            Param(
                "ground_refine_iterations",
                10,
                min=1,
                max=100,
                step=1,
                help="Least-squares refits of an initial floor against the cloud.",
            ),
            Param(
                "ground_max_tilt",
                45.0,
                min=1.0,
                max=89.0,
                step=1.0,
                unit="deg",
                help="Automatic floor: only planes within this angle of the camera's down "
                "direction are candidates (OpenPTrack: |b| >= 0.7).",
            ),
            Param(
                "ground_segment_distance",
                0.06,
                min=0.005,
                max=0.5,
                step=0.005,
                unit="m",
                help="Automatic floor: RANSAC inlier distance when segmenting planes.",
            ),
            Param(
                "ground_max_planes",
                6,
                min=1,
                max=20,
                step=1,
                help="Automatic floor: how many planes to segment before choosing the lowest.",
            ),
            Param(
                "ground_min_plane_points",
                100,
                min=3,
                max=100000,
                step=10,
                help="Automatic floor: a plane needs at least this many voxels.",
            ),
            Param(
                "ground_ransac_iterations",
                500,
                min=10,
                max=10000,
                step=10,
                help="Automatic floor: RANSAC iterations per plane (Open3D segment_plane).",
            ),
            # ---------------------------------------------------------- candidates
            Param(
                "min_height",
                1.0,
                min=0.3,
                max=2.5,
                step=0.05,
                unit="m",
                help="Shortest person (top of the head above the floor).",
            ),
            Param(
                "max_height",
                2.3,
                min=1.0,
                max=4.0,
                step=0.05,
                unit="m",
                help="Tallest person.",
            ),
            Param(
                "min_width",
                0.1,
                min=0.01,
                max=2.0,
                step=0.01,
                unit="m",
                help="Narrowest person (horizontal extent); also sets the fewest points of a "
                "cluster, min_height*min_width/voxel_size^2 (PCL).",
            ),
            Param(
                "max_width",
                8.0,
                min=0.2,
                max=20.0,
                step=0.1,
                unit="m",
                help="Widest cluster; also sets the most points of a cluster, "
                "max_height*max_width/voxel_size^2 (PCL).",
            ),
            Param(
                "cluster_tolerance",
                2.0,
                min=1.0,
                max=5.0,
                step=0.5,
                help="Euclidean clustering: points closer than this many voxel sizes join.",
            ),
            Param(
                "heads_minimum_distance",
                0.3,
                min=0.05,
                max=1.0,
                step=0.05,
                unit="m",
                help="Two heads closer than this on the floor are one person.",
            ),
            Param(
                "head_prominence",
                0.05,
                min=0.0,
                max=1.0,
                step=0.01,
                unit="m",
                help="A head stands out of its cluster's height profile by at least this "
                "(0: every local maximum, as PCL).",
            ),
            Param(
                "merge_distance",
                0.4,
                min=0.0,
                max=1.5,
                step=0.05,
                unit="m",
                help="Clusters whose heads are closer than this on the floor are merged first "
                "(PCL's min_distance_between_cluster_centers).",
            ),
            Param(
                "head_fraction",
                0.125,
                min=0.02,
                max=0.5,
                step=0.005,
                help="The head is this top fraction of a person's height (PCL: 1/8).",
            ),
            Param(
                "max_head_ratio",
                0.8,
                min=0.1,
                max=1.0,
                step=0.05,
                help="A person has a head: the floor extent of their top head_fraction is at "
                "most this fraction of their whole floor extent (1: no check, as PCL).",
            ),
            Param(
                "subcluster_min_points_factor",
                1.5,
                min=1.0,
                max=10.0,
                step=0.1,
                help="Only clusters with this many times the fewest points are split by heads.",
            ),
            Param(
                "centroid_depth_compensation",
                0.05,
                min=0.0,
                max=0.3,
                step=0.01,
                unit="m",
                help="Push the centroid this far along the viewing ray: the camera sees the "
                "body's surface, not its centre (OpenPTrack: 0.05).",
            ),
            # ----------------------------------------------------- classification
            Param(
                "use_rgb",
                True,
                help="Classify candidates with HOG on the colour (or infrared) image.",
            ),
            Param(
                "min_confidence",
                -3.0,
                min=-10.0,
                max=10.0,
                step=0.05,
                help="Keep candidates whose HOG+SVM score (OpenCV's people detector) is above "
                "this. OpenPTrack's -1.75 was for PCL's own SVM, whose scores run higher.",
            ),
            Param(
                "minimum_luminance",
                120,
                min=0,
                max=255,
                step=1,
                help="Below this mean image luminance, colour HOG is skipped and candidates are "
                "judged from depth alone.",
            ),
            Param(
                "min_depth_confidence",
                -3.0,
                min=-10.0,
                max=10.0,
                step=0.05,
                help="Depth-only judgement with depth_classifier hog: keep candidates whose "
                "silhouette HOG score (OpenCV's people detector) is above this.",
            ),
            Param(
                "depth_classifier",
                "trained",
                choices=("trained", "hog"),
                help="Depth-only judgement (dark frames, depth-only sensors): trained, the "
                "depth classifier trained on simulated depth (optrack train "
                "depth-classifier); hog, OpenCV's colour people detector on the silhouette.",
            ),
            Param(
                "min_depth_model_confidence",
                -0.5,
                min=-20.0,
                max=20.0,
                step=0.1,
                help="Depth-only judgement with depth_classifier trained: keep candidates whose "
                "log-odds of being a person are above this.",
            ),
            Param(
                "depth_model",
                "",
                help="The trained depth classifier's file (optrack train depth-classifier "
                "--out); empty: the one shipped with optrack.",
            ),
            Param(
                "hog_window_fill",
                0.75,
                min=0.3,
                max=1.0,
                step=0.05,
                help="Fraction of the 64x128 HOG window's height a person fills (PCL: 0.75).",
            ),
            Param(
                "hog_image",
                "auto",
                choices=("auto", "color", "infrared"),
                help="Image for HOG: colour; infrared after histogram equalisation (time-of-flight); "
                "auto: colour when the frame has it, else infrared.",
            ),
            Param(
                "edge_window",
                True,
                help="A candidate cut by the image's left or right border is also judged on its "
                "visible part, mirrored at the border (the window keeps the person's scale); "
                "the better score counts. Its floor position comes from its head.",
            ),
            Param(
                "edge_head_radius",
                0.09,
                min=0.03,
                max=0.3,
                step=0.01,
                unit="m",
                help="A head cut by the image's border is centred this far inside its visible "
                "inner edge (the person's floor position at the image's edge).",
            ),
            # ------------------------------------------------------------ background
            Param(
                "background_subtraction",
                False,
                help="Learn the empty scene and ignore it.",
            ),
            Param(
                "background_resolution",
                0.3,
                min=0.01,
                max=1.0,
                step=0.01,
                unit="m",
                help="Voxel size of the background occupancy map.",
            ),
            Param(
                "background_seconds",
                3.0,
                min=0.1,
                max=60.0,
                step=0.1,
                unit="s",
                help="How long the background is learnt for.",
            ),
            # ---------------------------------------------------------------- output
            Param(
                "box_enlarge_factor",
                1.1,
                min=1.0,
                max=2.0,
                step=0.05,
                help="The output image box is the head-to-floor height times this (OpenPTrack).",
            ),
            Param(
                "out_of_view_fraction",
                0.1,
                min=0.0,
                max=1.0,
                step=0.05,
                help="Flag a person partly out of view when more than this fraction of the "
                "head-to-floor box is outside the image.",
            ),
            Param(
                "occlusion_fraction",
                0.2,
                min=0.0,
                max=1.0,
                step=0.05,
                help="Flag a person occluded when more than this fraction of their box shows "
                "something nearer to the sensor.",
            ),
            Param(
                "occlusion_margin",
                0.3,
                min=0.05,
                max=2.0,
                step=0.05,
                unit="m",
                help="Nearer means nearer by at least this much.",
            ),
            Param(
                "person_radius",
                0.35,
                min=0.1,
                max=1.0,
                step=0.05,
                unit="m",
                help="A pixel belongs to a person when within this distance of the person's axis "
                "on the floor (silhouette, histogram).",
            ),
            Param(
                "histogram_hue_bins",
                16,
                min=1,
                max=180,
                step=1,
                help="Colour histogram of a person: hue bins.",
            ),
            Param(
                "histogram_saturation_bins",
                4,
                min=1,
                max=256,
                step=1,
                help="Colour histogram of a person: saturation bins.",
            ),
        ],
        help="Per-sensor people detection (OpenPTrack's ground-based cascade).",
    )
)

#: OpenPTrack's configuration per sensor model (and PCL's unit-test settings).
SENSOR_MODELS: dict[str, dict[str, Any]] = {
    "default": {},
    # OpenPTrack's Kinect and stereo detectors run HOG on colour only: in the dark,
    # they judge from depth (the luminance gate), not from the Kinect's infrared.
    # Kinect v1 reaches 8 m, not OpenPTrack's 5: OpenNI returns depth to about 8 m and a
    # person there is still a 1.7 m cluster (two simulated Kinect v1, people out to 10 m:
    # MOTA 0.68 with 5 m, 0.97 with 8 m; docs/detection.md).
    "kinect1": {"max_distance": 8.0, "sampling_factor": 4, "hog_image": "color"},
    # OpenPTrack subsamples Kinect v2's 960x540 registered cloud by 4; on the native
    # 512x424 depth image, 2 keeps about as many points (256x212 against 240x135).
    "kinect2": {"max_distance": 10.0, "sampling_factor": 2, "hog_image": "color"},
    "stereo": {"max_distance": 15.0, "sampling_factor": 4, "hog_image": "color"},
    "sr4500": {
        "max_distance": 10.0,
        "sampling_factor": 1,
        "min_confidence": -3.25,
        "min_height": 1.3,
        "confidence_threshold": 200,
        "hog_image": "infrared",
    },
    "pcl": {
        "max_distance": 50.0,
        "sampling_factor": 1,
        "min_height": 1.3,
        "max_height": 2.3,
        "min_width": 0.1,
        "max_width": 8.0,
        "min_confidence": -1.5,
        "minimum_luminance": 0,
        "ground_inlier_distance": 0.12,
        "centroid_depth_compensation": 0.0,
        "head_prominence": 0.0,
        "max_head_ratio": 1.0,
    },
}

#: Named overlays on a sensor model's parameters.
PRESETS: dict[str, dict[str, Any]] = {
    "children": {"min_height": 0.8, "heads_minimum_distance": 0.25},
}


def detection_params(
    model: str | None = None,
    preset: str | None = None,
    overrides: Mapping[str, Any] | None = None,
) -> Params:
    """Detection parameters for a sensor model, a preset on top, then overrides.

    An unknown model (e.g. a camera optrack has no figures for) gets the
    schema's defaults; an unknown preset is refused.
    """
    values: dict[str, Any] = dict(SENSOR_MODELS.get(model or "default", {}))
    if preset:
        if preset not in PRESETS:
            raise ParamError(f"detection has no preset '{preset}' (it has: {', '.join(PRESETS)}).")
        values.update(PRESETS[preset])
    if overrides:
        values.update(_for_model(overrides, model if model in SENSOR_MODELS else "default"))
    return DETECTION_PARAMS.create(values)


def _for_model(section: Mapping[str, Any], model: str) -> dict[str, Any]:
    """A ``detection`` section's values for one sensor model: the parameters it names
    for every sensor, then those under the model's own name on top."""
    values = {k: v for k, v in section.items() if k not in SENSOR_MODELS}
    values.update(section.get(model) or {})
    return values


def check_config_section(section: Mapping[str, Any]) -> None:
    """Refuse a config file's ``detection`` section that some sensor model cannot take.

    The section names parameters for every sensor and, under a sensor model's name
    (``kinect1: {max_distance: 8.0}``), parameters for that model's sensors only.
    """
    DETECTION_PARAMS.validate({k: v for k, v in section.items() if k not in SENSOR_MODELS})
    for model in SENSOR_MODELS:
        values = section.get(model)
        if values is not None and not isinstance(values, Mapping):
            raise ParamError(
                f"detection: '{model}' is a sensor model; give it parameters "
                f"(e.g. {model}: {{max_distance: 8.0}})."
            )
        try:
            DETECTION_PARAMS.validate(values or {})
        except ParamError as error:
            raise ParamError(f"under {model}, {error}") from None
