"""Per-sensor people detection: OpenPTrack's ground-based cascade (Munaro et al. 2012, 2016).

Preprocessing, ground plane, candidates in the ground-plane frame, HOG
classification, background subtraction, composed by :class:`PeopleDetector`.
"""

from optrack.detection.params import DETECTION_PARAMS, PRESETS, SENSOR_MODELS, detection_params
from optrack.detection.pipeline import PeopleDetector

__all__ = [
    "DETECTION_PARAMS",
    "PRESETS",
    "SENSOR_MODELS",
    "PeopleDetector",
    "detection_params",
]
