"""Where the window's data comes from: one small Qt interface.

A :class:`SiteSource` is what the window listens to and what it sends the
operator's intent to. The window does not know whether a site runs in this
process, on the bus, or not at all. Signals may be emitted from any thread
(a bus callback, a worker); Qt queues them to the window's thread.

The base class is the honest "no site": it never emits data, and it
answers every request with a sentence on :attr:`SiteSource.log` saying that
nothing was sent. :class:`app.bus_source.BusSource` subclasses it: it emits
the events of an :class:`optrack.client.SiteClient` as these signals and
hands it the requests.

Status dictionaries (``status(node, values)``) are shown as they come; the
keys the Sensors dock puts in columns are listed in :data:`SENSOR_STATUS_KEYS`
and the Outputs dock reads the ``outputs`` node's ``destinations`` (see
docs/gui.md).
"""

from __future__ import annotations

from typing import Any

from PySide6.QtCore import QObject, Signal

from optrack.params import REGISTRY, Schema

__all__ = [
    "NO_SITE",
    "NODE_STAGES",
    "SENSOR_STATUS_KEYS",
    "SiteSource",
    "node_schemas",
]

NO_SITE = "No site connected"

# Status keys of a sensor's node shown as columns: (key, column title, format).
SENSOR_STATUS_KEYS: tuple[tuple[str, str, str], ...] = (
    ("fps", "fps", "{:.1f}"),
    ("latency_ms", "latency\n(ms)", "{:.0f}"),
    ("clock_offset_ms", "offset\n(ms)", "{:+.1f}"),
    ("dropped", "dropped", "{:d}"),
    ("last_error", "last error", "{}"),
)

# The stages the site's nodes take live updates for, shown before a site says which it has.
NODE_STAGES = (
    "detection",
    "tracking",
    "appearance",
    "smoothing",
    "outputs",
    "skeleton_live",
    "skeleton",
    "skeleton_fusion",
)


def node_schemas() -> dict[str, Schema]:
    """The schemas of the nodes' live stages, after importing every module whose stages a
    node may run (as ``optrack.runtime.config`` does), so a site's stages are all known."""
    from optrack.runtime.config import register_node_stages

    register_node_stages()
    return {stage: REGISTRY[stage] for stage in NODE_STAGES if stage in REGISTRY}


class SiteSource(QObject):
    """The window's one data source; the base class is "no site connected".

    Signals (what the site tells the window):

    * ``tracks(TrackBatch)``: the tracker's output.
    * ``detections(DetectionBatch)``: one sensor's detections (world frame).
    * ``calibration(NetworkCalibration)``: the calibration the nodes use.
    * ``status(str node, dict values)``: a node's status (see module docstring).
    * ``preview(str sensor, RGBDFrame frame, object batch)``: a down-sampled
      frame and the detections found in it (a ``DetectionBatch`` or None);
      detection boxes are in the preview's depth-image pixels.
    * ``cloud(str sensor, ndarray points)``: a decimated point cloud, Nx3 float32
      in the world frame (when the site sends none, the window makes one from
      the preview and the calibration).
    * ``schemas(dict stage -> Schema, dict stage -> dict values)``: the
      parameters the nodes take and their current values.
    * ``log(str level, str text)``: a sentence for the operator; level is
      ``info``, ``warning`` or ``error``.
    * ``connection(str description)``: the site now connected ("" when none).
    * ``command_reply(str action, bool ok, str sentence, object result)``: the
      answer to a recording or playback request (``result``: node -> its answer).
    * ``skeletons(SkeletonBatch)``: the skeletons, while the skeleton stage runs.
    """

    tracks = Signal(object)
    detections = Signal(object)
    calibration = Signal(object)
    status = Signal(str, object)  # object: a dict passes as it is, not as a QVariantMap
    preview = Signal(str, object, object)
    cloud = Signal(str, object)
    schemas = Signal(object, object)
    log = Signal(str, str)
    connection = Signal(str)
    command_reply = Signal(str, bool, str, object)
    skeletons = Signal(object)

    def describe(self) -> str:
        """One line for the status bar: which site this is."""
        return NO_SITE

    @property
    def connected(self) -> bool:
        return False

    # ----------------------------------------------------- operator's intent
    def set_params(self, stage: str, values: dict[str, Any]) -> None:
        """Apply validated parameter values to the nodes running ``stage``."""
        names = ", ".join(f"{stage}.{name}" for name in values)
        self.log.emit("warning", f"{NO_SITE}: {names} was not sent to any node.")

    def add_output(self, kind: str, address: str) -> None:
        """Start streaming tracks to a destination (``kind`` in
        :data:`optrack.outputs.streams.OUTPUT_KINDS`)."""
        self.log.emit("warning", f"{NO_SITE}: the {kind} output {address} was not started.")

    def remove_output(self, kind: str, address: str) -> None:
        self.log.emit("warning", f"{NO_SITE}: the {kind} output {address} was not stopped.")

    def enable_output(self, kind: str, address: str, enabled: bool) -> None:
        verb = "enabled" if enabled else "disabled"
        self.log.emit("warning", f"{NO_SITE}: the {kind} output {address} was not {verb}.")

    def start_recording(self, folder: str) -> None:
        """Every detector node records its sensor into ``folder`` (on its own computer)."""
        self._refuse("record_start", f"{NO_SITE}: no recording was started.")

    def stop_recording(self) -> None:
        self._refuse("record_stop", f"{NO_SITE}: there is no recording to stop.")

    def playback(self, action: str, **args: Any) -> None:
        """``action`` (pause, resume, step, speed with ``value``) on every replayed sensor."""
        self._refuse(action, f"{NO_SITE}: there is no playback to {action}.")

    def _refuse(self, action: str, sentence: str) -> None:
        self.log.emit("warning", sentence)
        self.command_reply.emit(action, False, sentence, {})

    def close(self) -> None:
        """Disconnect and release what the source holds; idempotent."""
