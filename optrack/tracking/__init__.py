"""Central people tracker: UKF motion model, gated global-nearest-neighbour association,
track life-cycle, appearance recovery and output smoothing (OpenPTrack section 6,
Munaro 2012 section 5)."""

from optrack.tracking.params import APPEARANCE_PARAMS, SMOOTHING_PARAMS, TRACKING_PARAMS
from optrack.tracking.smoothing import OutputSmoother, heartbeat_message, tracks_message
from optrack.tracking.tracker import Tracker, TrackerStatus, TrackingError

__all__ = [
    "APPEARANCE_PARAMS",
    "SMOOTHING_PARAMS",
    "TRACKING_PARAMS",
    "OutputSmoother",
    "Tracker",
    "TrackerStatus",
    "TrackingError",
    "heartbeat_message",
    "tracks_message",
]
