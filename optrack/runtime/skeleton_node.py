"""The skeleton stage on the bus: each person's points from every sensor in, skeletons out.

Switched on per site by ``skeleton_live.enabled`` (``optrack run --skeleton``;
off by default, and then nothing below runs). While it is on:

- each detector node crops, after each frame, every person it detected from
  its own depth points (:func:`person_clouds_message`: the person's vertical
  cylinder, :func:`optrack.skeleton.fusion.person_cloud`, from every
  ``skeleton_live.stride``-th depth pixel, decimated to at most
  ``skeleton_fusion.points``) and publishes them, float16 around the person,
  on ``person_clouds/<sensor>``;
- the skeleton node (this module; ``python -m optrack.runtime.skeleton_node
  --site NAME [--config FILE]``, started by ``optrack run`` when the stage
  is on) gives each sensor's person to the track nearest on the floor
  (within ``gate_m``, tracks from ``tracks``), fuses per track the newest
  cloud of every sensor no older than ``window_s`` before the newest one
  (world frame; decimated again), runs one
  :class:`~optrack.skeleton.tracker.SkeletonTracker` per track and publishes
  a :class:`~optrack.types.SkeletonBatch` on ``skeletons`` after each round
  of updates; the outputs node sends it (OpenPTrack v2's pose message, OSC).

A track gone from the tracks, or without points, for ``drop_after_s`` loses
its skeleton. A person's clouds that arrive while the node is busy are
coalesced: each round uses the newest of each sensor, so a slow skeleton
update lowers the skeleton's rate (``rate_hz``), never the detectors'.
Turning ``skeleton_live.enabled`` off on the nodes (the Parameters dock)
stops the clouds and the skeletons at once; on again, they resume.
"""

from __future__ import annotations

import collections
import dataclasses
import logging
import math
import sys
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from optrack.net.bus import Bus
from optrack.net.messages import (
    MAX_PERSON_POINTS,
    PersonCloud,
    PersonCloudsMessage,
    SkeletonsMessage,
    TracksMessage,
)
from optrack.params import Params
from optrack.runtime.node import Node, RateMeter, live_schemas
from optrack.runtime.skeleton_params import SKELETON_LIVE_PARAMS
from optrack.types import Detection, RGBDFrame, Skeleton, SkeletonBatch, TrackBatch

if TYPE_CHECKING:
    from optrack.skeleton.tracker import SkeletonEstimate, SkeletonTracker

__all__ = [
    "SKELETON_LIVE_PARAMS",
    "SkeletonClouds",
    "SkeletonNode",
    "main",
    "person_clouds_message",
    "run_skeleton_node",
]

log = logging.getLogger("optrack.runtime.skeleton")


def person_clouds_message(
    sensor: str,
    stamp: float,
    frame: RGBDFrame,
    world_T_camera: np.ndarray,
    detections: list[Detection],
    fusion: Params,
    rng: np.random.Generator,
) -> PersonCloudsMessage:
    """Each detected person's decimated points from this sensor's frame (world frame,
    float16 around the person), for the skeleton node."""
    from optrack.skeleton.fusion import person_cloud

    floor = np.array([[d.x, d.y] for d in detections], dtype=np.float64).reshape(-1, 2)
    clouds = []
    for k, detection in enumerate(detections):
        mine = person_cloud(
            {sensor: frame},
            {sensor: world_T_camera},
            floor[k],
            detection.height,
            fusion,
            rng,
            others=np.delete(floor, k, axis=0),
        )
        if len(mine) > MAX_PERSON_POINTS:  # what one message may carry
            mine = mine[rng.choice(len(mine), MAX_PERSON_POINTS, replace=False)]
        offsets = (mine - np.array([detection.x, detection.y, 0.0])).astype(np.float16)
        clouds.append(
            PersonCloud(
                x=float(detection.x),
                y=float(detection.y),
                height=float(detection.height),
                points=offsets[np.all(np.isfinite(offsets), axis=1)].tobytes(),
            )
        )
    return PersonCloudsMessage(sensor=sensor, stamp=float(stamp), clouds=clouds)


class SkeletonClouds:
    """A detector node's part of the skeleton stage: while ``skeleton_live.enabled``,
    each frame's people's points on ``person_clouds/<sensor>``. Its stages join the
    node's ``live`` ones (changed through ``params/<sensor>``)."""

    def __init__(
        self,
        bus: Bus,
        sensor: str,
        live: dict[str, Params],
        stages: dict[str, Params] | None = None,
    ) -> None:
        from optrack.skeleton.fusion import FUSION_PARAMS

        stages = dict(stages or {})
        self.bus = bus
        self.sensor = sensor
        self.params = stages.get("skeleton_live") or SKELETON_LIVE_PARAMS.create()
        self.fusion = stages.get("skeleton_fusion") or FUSION_PARAMS.create()
        live["skeleton_live"] = self.params
        live["skeleton_fusion"] = self.fusion
        self.published = 0
        self.failures = 0
        self._rng = np.random.default_rng(0)
        self._crop: Params | None = None  # skeleton_fusion with skeleton_live.stride

    def crop_params(self) -> Params:
        """The ``skeleton_fusion`` values with the live ``stride`` (rebuilt when changed)."""
        values = {**self.fusion.as_dict(), "stride": int(self.params.stride)}
        if self._crop is None or self._crop.as_dict() != values:
            self._crop = self.fusion.schema.create(values)
        return self._crop

    def offer(self, frame: RGBDFrame, batch: Any, world_T_camera: np.ndarray | None) -> None:
        """After a frame's detections: its people's points, when the stage is on and the
        sensor calibrated (a failure is counted and logged once, never stops detection)."""
        if not self.params.enabled or world_T_camera is None or not batch.detections:
            return
        try:
            message = person_clouds_message(
                self.sensor,
                batch.stamp,
                frame,
                world_T_camera,
                batch.detections,
                self.crop_params(),
                self._rng,
            )
        except Exception as error:
            self.failures += 1
            if self.failures == 1:
                log.error("cropping people's points failed: %s", error, exc_info=error)
            return
        self.bus.publish(self.bus.keys.person_clouds(self.sensor), message)
        self.published += 1


@dataclasses.dataclass
class _Person:
    """One track's skeleton and the newest points of each sensor."""

    tracker: SkeletonTracker
    height: float
    clouds: dict[str, tuple[float, np.ndarray]] = dataclasses.field(default_factory=dict)
    fresh: bool = False
    seen: float = 0.0  # node clock when its track or points were last seen
    estimate: SkeletonEstimate | None = None
    meter: RateMeter = dataclasses.field(default_factory=RateMeter)


class SkeletonNode(Node):
    """Person clouds and tracks in, skeletons out (see the module docstring)."""

    role = "skeleton"

    def __init__(
        self,
        bus: Bus,
        node_params: Params,
        live: dict[str, Params] | None = None,
        clock: Callable[[], float] = time.monotonic,
        logger: logging.Logger = log,
    ) -> None:
        from optrack.skeleton.fusion import FUSION_PARAMS
        from optrack.skeleton.params import SKELETON_PARAMS

        live = live_schemas(
            live,
            node_params,
            {
                "skeleton_live": SKELETON_LIVE_PARAMS,
                "skeleton": SKELETON_PARAMS,
                "skeleton_fusion": FUSION_PARAMS,
            },
        )
        super().__init__(bus, "skeleton", node_params, live, logger)
        self.params = live["skeleton_live"]
        self.clock = clock
        self.people: dict[int, _Person] = {}
        self.tracks: TrackBatch | None = None
        self.published = 0
        self.updates = 0
        self.unmatched = 0
        self.failures = 0
        self._clouds_in: collections.deque[PersonCloudsMessage] = collections.deque(maxlen=256)
        self._arrived = threading.Event()
        self._rng = np.random.default_rng(0)
        self._meter = RateMeter()
        self._latency = RateMeter()
        self._update_s = RateMeter()
        bus.subscribe(bus.keys.person_clouds(), PersonCloudsMessage, self._on_clouds)
        bus.subscribe(bus.keys.tracks, TracksMessage, self._on_tracks)

    def _on_clouds(self, message: PersonCloudsMessage, key: str) -> None:
        self._clouds_in.append(message)
        self._arrived.set()

    def _on_tracks(self, message: TracksMessage, key: str) -> None:
        self.tracks = message.batch

    # ----------------------------------------------------------------- rounds
    def step(self, timeout: float = 0.1) -> int:
        """Take the clouds that arrived (waiting up to ``timeout``), update the skeletons
        of the tracks with new points, publish them. Returns how many were updated."""
        self.apply_params()
        if not self._clouds_in:
            self._arrived.wait(timeout)
        self._arrived.clear()
        messages = []
        while self._clouds_in:
            messages.append(self._clouds_in.popleft())
        if not self.params.enabled:
            self.people.clear()
            self.state = "idle"
            return 0
        self.state = "running"
        now = self.clock()
        self._match(messages, now)
        updated = [person for person in self.people.values() if person.fresh]
        newest = -math.inf
        for person in updated:
            try:
                newest = max(newest, self._update(person))
            except Exception as error:  # one skeleton's failure never stops the others
                person.fresh = False
                self.failures += 1
                self.last_error = f"a skeleton update failed ({type(error).__name__}: {error})"
                if self.failures == 1:
                    self.log.error("%s; further failures are only counted.", self.last_error)
        self._drop(now)
        if newest > -math.inf:
            self._publish(newest)
        return len(updated)

    def _match(self, messages: list[PersonCloudsMessage], now: float) -> None:
        """Give each sensor's person to the nearest track within ``gate_m``."""
        tracks = self.tracks.tracks if self.tracks is not None else []
        if not tracks:
            self.unmatched += sum(len(m.clouds) for m in messages)
            return
        where = np.array([[t.x, t.y] for t in tracks])
        gate = float(self.params.gate_m)
        for message in messages:
            for cloud in message.clouds:
                distance = np.hypot(where[:, 0] - cloud.x, where[:, 1] - cloud.y)
                k = int(np.argmin(distance))
                if distance[k] > gate:
                    self.unmatched += 1
                    continue
                person = self._person(tracks[k].id, tracks[k].height)
                if person is None:
                    continue
                stored = person.clouds.get(message.sensor)
                if stored is None or stored[0] <= message.stamp:
                    person.clouds[message.sensor] = (message.stamp, cloud.world_points())
                    person.fresh = True
                    person.seen = now
        for track in tracks:  # a person whose track goes on is still there
            if track.id in self.people:
                self.people[track.id].height = float(track.height)

    def _person(self, track_id: int, height: float) -> _Person | None:
        person = self.people.get(track_id)
        if person is None:
            if len(self.people) >= int(self.params.max_people):
                return None
            from optrack.skeleton.tracker import SkeletonTracker

            person = self.people[track_id] = _Person(
                SkeletonTracker(self.live["skeleton"], seed=track_id), float(height)
            )
        return person

    def _update(self, person: _Person) -> float:
        """One skeleton update from the person's fused cloud; returns its stamp."""
        from optrack.skeleton.fusion import decimate

        newest = max(stamp for stamp, _ in person.clouds.values())
        window = float(self.params.window_s)
        parts = [pts for stamp, pts in person.clouds.values() if stamp >= newest - window]
        fusion = self.live["skeleton_fusion"]
        points = decimate(np.concatenate(parts), float(fusion.voxel), int(fusion.points), self._rng)
        started = time.perf_counter()
        person.estimate = person.tracker.update(points, newest)
        self._update_s.add(time.perf_counter() - started)
        person.meter.add()
        person.fresh = False
        self.updates += 1
        return newest

    def _drop(self, now: float) -> None:
        limit = float(self.params.drop_after_s)
        for track_id in [k for k, p in self.people.items() if now - p.seen > limit]:
            del self.people[track_id]

    def batch(self, stamp: float) -> SkeletonBatch:
        """Every current skeleton (joints left out while lost), stamped ``stamp``."""
        from optrack.skeleton.joints import JOINTS

        skeletons = []
        for track_id, person in sorted(self.people.items()):
            estimate = person.estimate
            if estimate is None:
                continue
            joints: dict[str, tuple[float, float, float, float]] = {}
            if estimate.state != "lost":
                for name, xyz, confidence in zip(
                    JOINTS, estimate.joints, estimate.confidence, strict=True
                ):
                    if np.all(np.isfinite(xyz)):
                        joints[name] = (*(float(v) for v in xyz), float(confidence))  # type: ignore[assignment]
            skeletons.append(
                Skeleton(
                    id=int(track_id),
                    height=float(person.height),
                    state=str(estimate.state),
                    rate_hz=float(person.meter.rate()),
                    joints=joints,
                )
            )
        return SkeletonBatch(stamp=float(stamp), seq=self.published, skeletons=skeletons)

    def _publish(self, stamp: float) -> None:
        self.bus.publish(self.bus.keys.skeletons, SkeletonsMessage(batch=self.batch(stamp)))
        self.published += 1
        self._meter.add()
        self._latency.add(time.time() - stamp)

    def status_fields(self) -> dict[str, Any]:
        states = collections.Counter(
            p.estimate.state for p in self.people.values() if p.estimate is not None
        )
        return {
            "fps": self._meter.rate(),
            "latency_ms": self._latency.median() * 1000.0,
            "values": {
                "enabled": bool(self.params.enabled),
                "skeletons": len(self.people),
                "tracking": states.get("tracking", 0),
                "initialising": states.get("initialising", 0),
                "lost": states.get("lost", 0),
                "updates": self.updates,
                "published": self.published,
                "unmatched_clouds": self.unmatched,
                "failures": self.failures,
                "update_ms": self._update_s.median() * 1000.0,
            },
        }

    def run(self) -> int:
        self.start_status()
        self.publish_status()
        try:
            while not self.stopping:
                self.step()
        finally:
            self.close()
        return 0


def run_skeleton_node(site: str, config_path: str | None = None) -> int:
    """The skeleton node as a process (``python -m optrack.runtime.skeleton_node``)."""
    from optrack.net.keys import check_name
    from optrack.runtime.config import load_node_config
    from optrack.runtime.process import finish, nice, setup_logging, stop_on_signals

    config = load_node_config(config_path)
    check_name("site", site)
    nice(config["node"])
    setup_logging("optrack node skeleton")
    bus = Bus(site, "skeleton", config["bus"], host=False)
    try:
        stages = ("skeleton_live", "skeleton", "skeleton_fusion")
        node = SkeletonNode(bus, config["node"], {stage: config[stage] for stage in stages})
        with stop_on_signals(node.stop):
            code = node.run()
    finally:
        bus.close()
    return finish(code)


def main(argv: list[str] | None = None) -> int:
    """``python -m optrack.runtime.skeleton_node --site NAME [--config FILE]``."""
    from optrack.runtime.process import module_main

    return module_main(
        argv,
        "optrack.runtime.skeleton_node",
        "Skeleton node: people's points from the detectors in, skeletons out.",
        run_skeleton_node,
    )


if __name__ == "__main__":
    sys.exit(main())
