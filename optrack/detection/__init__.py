"""Per-sensor people detection: OpenPTrack's ground-based cascade (Munaro et al. 2012, 2016).

Preprocessing, ground plane, candidates in the ground-plane frame, HOG
classification, background subtraction, composed by :class:`PeopleDetector`.
"""

from optrack.lazy import lazy_exports

# Imported on first use, so that a light module of this package (its cli.py, for
# `optrack --help`) loads nothing heavy.
_HOMES = {
    "DETECTION_PARAMS": "optrack.detection.params",
    "PRESETS": "optrack.detection.params",
    "SENSOR_MODELS": "optrack.detection.params",
    "detection_params": "optrack.detection.params",
    "PeopleDetector": "optrack.detection.pipeline",
}


__getattr__ = lazy_exports(__name__, _HOMES)

__all__ = [
    "DETECTION_PARAMS",
    "PRESETS",
    "SENSOR_MODELS",
    "PeopleDetector",
    "detection_params",
]
