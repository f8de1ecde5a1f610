"""The outputs node: tracks from the bus to UDP JSON, OSC and WebSocket.

It runs inside the tracker node's process (``optrack node track``, ``optrack
run``), which hands it every tracks frame directly (:meth:`OutputsNode.send`,
no bus hop before the datagram), or as its own process taking the tracks
from the bus (``python -m optrack.runtime.outputs_node --site NAME --config
FILE``; one more hop, for a computer of its own). Either way it takes the
skeletons (``skeletons``, while the skeleton stage runs) from the bus and sends
them to the same destinations. Its name on the
bus is ``outputs``: its status lists every destination with what was sent
and the errors, and parameter updates on ``params/outputs`` (stage
``outputs``) add, change or remove destinations while it runs; a
destination that cannot be used is refused and the running ones are kept.
"""

from __future__ import annotations

import logging
import sys
import time
from typing import Any

from optrack.net.bus import Bus
from optrack.net.messages import SkeletonsMessage, TracksMessage
from optrack.outputs.streams import Outputs
from optrack.params import Params
from optrack.runtime.node import Node, RateMeter
from optrack.types import SkeletonBatch, TrackBatch

__all__ = ["OutputsNode", "main"]

log = logging.getLogger("optrack.runtime.outputs")


class OutputsNode(Node):
    """Tracks in, datagrams out (see the module docstring)."""

    role = "outputs"

    def __init__(
        self,
        bus: Bus,
        node_params: Params,
        outputs_params: Params,
        logger: logging.Logger = log,
        subscribe: bool = True,
    ) -> None:
        """``subscribe``: take the tracks from the bus; otherwise the caller hands every
        frame to :meth:`send`."""
        self.outputs = Outputs(outputs_params.schema.create(outputs_params.as_dict()))
        super().__init__(bus, "outputs", node_params, {"outputs": outputs_params}, logger)
        self._meter = RateMeter()
        self._latency = RateMeter()
        self._last_stamp: float | None = None
        self.skeleton_frames = 0
        if subscribe:
            bus.subscribe(bus.keys.tracks, TracksMessage, self._on_tracks)
        bus.subscribe(bus.keys.skeletons, SkeletonsMessage, self._on_skeletons)
        self.state = "running"

    def _on_params(self, message: Any, key: str) -> None:
        # No frames to wait for: apply at once (on the bus's thread).
        super()._on_params(message, key)
        self.apply_params()

    def on_params(self, stage: str, changed: dict[str, Any]) -> None:
        self.outputs.configure(changed)  # an OutputError refuses the whole update

    def _on_tracks(self, message: TracksMessage, key: str) -> None:
        self.send(message.batch)

    def _on_skeletons(self, message: SkeletonsMessage, key: str) -> None:
        self.send_skeletons(message.batch)

    def send_skeletons(self, batch: SkeletonBatch) -> None:
        """Send one frame of skeletons to every destination now."""
        self.outputs.publish_skeletons(batch)
        self.skeleton_frames += 1

    def send(self, batch: TrackBatch) -> None:
        """Send one tracks frame to every destination now."""
        self.outputs.publish(batch)
        now = time.monotonic()
        self._meter.add(now=now)
        if batch.stamp != self._last_stamp:  # a repeat carries no new frame
            self._latency.add(time.time() - batch.stamp, now)
        self._last_stamp = batch.stamp

    def status_fields(self) -> dict[str, Any]:
        return {
            "fps": self._meter.rate(),
            "latency_ms": self._latency.median() * 1000.0,
            "destinations": self.outputs.status(),
            "values": {
                "frames": self.outputs.frames,
                "heartbeats": self.outputs.heartbeat_seq,
                "max_id": self.outputs.max_id,
                "skeleton_frames": self.skeleton_frames,
            },
        }

    def close(self) -> None:
        self.outputs.close()
        super().close()

    def run(self) -> int:
        self.start_status()
        self.publish_status()
        try:
            while not self._stop.wait(0.5):
                pass
        finally:
            self.close()
        return 0


def main(argv: list[str] | None = None) -> int:
    """``python -m optrack.runtime.outputs_node --site NAME [--config FILE]``."""
    from optrack.runtime.process import module_main, run_outputs_node

    return module_main(
        argv,
        "optrack.runtime.outputs_node",
        "Outputs node: tracks from the bus to UDP JSON, OSC and WebSocket.",
        run_outputs_node,
    )


if __name__ == "__main__":
    sys.exit(main())
