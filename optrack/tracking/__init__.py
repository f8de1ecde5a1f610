"""Central people tracker: UKF motion model, gated global-nearest-neighbour association,
track life-cycle, appearance recovery and output smoothing (OpenPTrack section 6,
Munaro 2012 section 5)."""

from optrack.lazy import lazy_exports

# Imported on first use, so that a node registering the tracking stage's parameters
# (optrack.tracking.params) does not load the filter (filterpy, scipy.stats).
_HOMES = {
    "APPEARANCE_PARAMS": "optrack.tracking.params",
    "SMOOTHING_PARAMS": "optrack.tracking.params",
    "TRACKING_PARAMS": "optrack.tracking.params",
    "OutputSmoother": "optrack.tracking.smoothing",
    "heartbeat_message": "optrack.tracking.smoothing",
    "tracks_message": "optrack.tracking.smoothing",
    "Tracker": "optrack.tracking.tracker",
    "TrackerStatus": "optrack.tracking.tracker",
    "TrackingError": "optrack.tracking.tracker",
}

__getattr__ = lazy_exports(__name__, _HOMES)

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
