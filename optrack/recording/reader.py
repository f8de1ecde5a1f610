"""Read recordings frame by frame, all sensors merged in timestamp order."""

from __future__ import annotations

import heapq
import logging
import os
from collections.abc import Iterable, Iterator
from pathlib import Path, PurePosixPath

import cv2
import msgspec
import numpy as np
import yaml

from optrack.recording.format import (
    FORMAT_NAME,
    FORMAT_VERSION,
    GROUND_TRUTH,
    INDEX,
    MANIFEST,
    SENSOR_ID,
    SENSORS_DIR,
    STREAMS,
    GroundTruth,
    IndexEntry,
    Manifest,
    RecordingError,
    SensorInfo,
)
from optrack.types import RGBDFrame, pose_problem

__all__ = ["Recording", "is_recording"]

log = logging.getLogger("optrack.recording")


def is_recording(path: str | os.PathLike[str]) -> bool:
    """True when ``path`` is a directory holding a recording manifest."""
    return (Path(path) / MANIFEST).is_file()


def _read_jsonl(path: Path, kind: type[msgspec.Struct]) -> Iterator[msgspec.Struct]:
    """Lines of an append-only JSONL file, each with a time ``t`` that never goes back (as
    the writer checks); a last line cut short by a killed writer is skipped."""
    decoder = msgspec.json.Decoder(kind)
    last = -float("inf")
    with path.open("rb") as handle:
        number = 0
        for raw in handle:
            number += 1
            if not raw.endswith(b"\n"):
                return  # the writer was killed while writing this line
            if not raw.strip():
                continue
            try:
                item = decoder.decode(raw)
            except msgspec.DecodeError as error:
                raise RecordingError(f"{path} line {number} is damaged ({error}).") from None
            if item.t < last:  # type: ignore[attr-defined]
                raise RecordingError(
                    f"{path} line {number} is damaged: its time t={item.t:.6f} s goes back "  # type: ignore[attr-defined]
                    f"from t={last:.6f} s on the line before (a recording is in time order)."
                )
            last = item.t  # type: ignore[attr-defined]
            yield item


def _check_sensor(info: SensorInfo, manifest: Path) -> None:
    """The writer's checks of a sensor's entry, and values no sensor has."""
    if not SENSOR_ID.match(info.id):
        problem = "an id that cannot name a folder (letters, digits, '_', '-' or '.')"
    elif not 0 < info.depth_scale < float("inf"):
        problem = f"depth_scale {info.depth_scale} (metres per depth unit, above 0)"
    elif info.fps is not None and not 0 < info.fps < float("inf"):
        problem = f"fps {info.fps} (frames per second, above 0)"
    elif info.world_T_camera is not None and (
        reason := pose_problem(np.asarray(info.world_T_camera, dtype=np.float64))
    ):
        problem = f"a world_T_camera that {reason}"
    else:
        return
    raise RecordingError(f"{manifest} is damaged: sensor '{info.id}' has {problem}.")


class Recording:
    """A recording opened for reading. Cheap to open: nothing but the manifest is read."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        if not self.path.exists():
            raise RecordingError(f"recording {self.path} does not exist; check the path.")
        if not self.path.is_dir():
            raise RecordingError(
                f"{self.path} is a file, not a recording directory (record one with 'optrack record' "
                "or 'optrack sim')."
            )
        manifest_path = self.path / MANIFEST
        if not manifest_path.is_file():
            raise RecordingError(
                f"{self.path} is not an optrack recording (it has no {MANIFEST}); record one with "
                "'optrack record' or 'optrack sim'."
            )
        try:
            data = yaml.safe_load(manifest_path.read_text(encoding="utf-8"))
        except yaml.YAMLError:
            raise RecordingError(f"{manifest_path} is damaged (not valid YAML).") from None
        if not isinstance(data, dict) or data.get("format") != FORMAT_NAME:
            raise RecordingError(
                f"{self.path} is not an optrack recording ({MANIFEST} does not say "
                f"format: {FORMAT_NAME})."
            )
        version = data.get("version")
        if version != FORMAT_VERSION:
            raise RecordingError(
                f"recording {self.path} has format version {version}; this optrack reads version "
                f"{FORMAT_VERSION}. Use a matching optrack to convert it."
            )
        try:
            self.manifest: Manifest = msgspec.convert(data, Manifest)
        except msgspec.ValidationError as error:
            raise RecordingError(f"{manifest_path} is damaged ({error}).") from None
        for info in self.manifest.sensors:
            _check_sensor(info, manifest_path)
        self.sensors: dict[str, SensorInfo] = {s.id: s for s in self.manifest.sensors}
        self._told: set[str] = set()  # the parts already said to be partial

    # ------------------------------------------------------------------ index
    @property
    def sensor_ids(self) -> list[str]:
        return list(self.sensors)

    def _sensor(self, sensor_id: str) -> SensorInfo:
        try:
            return self.sensors[sensor_id]
        except KeyError:
            raise RecordingError(
                f"recording {self.path} has no sensor '{sensor_id}' (it has: {', '.join(self.sensors)})."
            ) from None

    def index(self, sensor_id: str) -> Iterator[IndexEntry]:
        """The index entries of one sensor, in time order."""
        self._sensor(sensor_id)
        path = self.path / SENSORS_DIR / sensor_id / INDEX
        frames = self.manifest.extra.get("frames")
        announced = frames.get(sensor_id) if isinstance(frames, dict) else None
        entries = _read_jsonl(path, IndexEntry) if path.is_file() else iter(())
        return self._counted(entries, f"sensor '{sensor_id}'", "frames", announced)  # type: ignore[arg-type]

    def count(self, sensor_id: str) -> int:
        return sum(1 for _ in self.index(sensor_id))

    @property
    def has_ground_truth(self) -> bool:
        return self.manifest.ground_truth and (self.path / GROUND_TRUTH).is_file()

    def ground_truth(self) -> Iterator[GroundTruth]:
        """Ground truth instants in time order (empty when the recording has none)."""
        path = self.path / GROUND_TRUTH
        if not path.is_file() and not self.manifest.ground_truth:
            return iter(())
        announced = self.manifest.extra.get("ground_truth_instants")
        instants = _read_jsonl(path, GroundTruth) if path.is_file() else iter(())
        return self._counted(instants, "the ground truth", "instants", announced)  # type: ignore[arg-type]

    def _counted(
        self, items: Iterator[msgspec.Struct], part: str, unit: str, announced: object
    ) -> Iterator[msgspec.Struct]:
        """``items`` as they come; once they end short of the count the manifest announces,
        one sentence (once per part) says how much is missing."""
        count = 0
        for item in items:
            count += 1
            yield item
        if isinstance(announced, int) and 0 <= count < announced and part not in self._told:
            self._told.add(part)
            log.warning(
                "recording %s is partial: %s holds %d of the %d %s its manifest announces "
                "(%d missing, %.0f%%); only what is there is used.",
                self.path,
                part,
                count,
                announced,
                unit,
                announced - count,
                100.0 * (announced - count) / announced,
            )

    # ----------------------------------------------------------------- frames
    def load(
        self, sensor_id: str, entry: IndexEntry, streams: Iterable[str] = STREAMS
    ) -> RGBDFrame:
        """Load the images of one index entry as a frame."""
        info = self._sensor(sensor_id)
        streams = set(streams)
        root = self.path / SENSORS_DIR / sensor_id
        images: dict[str, np.ndarray | None] = {}
        for kind in STREAMS:
            relative = getattr(entry, kind)
            if relative is None or (kind != "depth" and kind not in streams):
                images[kind] = None
                continue
            if PurePosixPath(relative).is_absolute() or ".." in PurePosixPath(relative).parts:
                raise RecordingError(
                    f"recording {self.path} is damaged: sensor '{sensor_id}' frame {entry.seq} "
                    f"names {kind} image '{relative}', outside the sensor's folder; index "
                    "entries name files inside it (e.g. depth/00000000.png)."
                )
            file = root / relative
            image = cv2.imread(str(file), cv2.IMREAD_UNCHANGED)
            if image is None:
                raise RecordingError(
                    f"recording {self.path} is damaged: {file.relative_to(self.path)} is missing or "
                    "unreadable."
                )
            if kind == "color":
                image = cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
            images[kind] = image
        return RGBDFrame(
            depth=images["depth"],  # type: ignore[arg-type]
            intrinsics=info.intrinsics,
            sensor_id=sensor_id,
            timestamp=entry.t,
            depth_scale=info.depth_scale,
            color=images["color"],
            infrared=images["infrared"],
            confidence=images["confidence"],
            color_intrinsics=info.color_intrinsics,
            seq=entry.seq,
        )

    def frame(self, sensor_id: str, position: int) -> RGBDFrame:
        """The ``position``-th frame of a sensor (0-based)."""
        for i, entry in enumerate(self.index(sensor_id)):
            if i == position:
                return self.load(sensor_id, entry)
        raise RecordingError(
            f"sensor '{sensor_id}' of recording {self.path} has no frame {position} "
            f"(it has {self.count(sensor_id)})."
        )

    def frames(
        self, sensors: Iterable[str] | None = None, streams: Iterable[str] = STREAMS
    ) -> Iterator[RGBDFrame]:
        """All frames of the chosen sensors in timestamp order, one at a time."""
        chosen = list(sensors) if sensors is not None else self.sensor_ids
        streams = tuple(streams)
        for sid in chosen:
            self._sensor(sid)

        def keyed(sid: str) -> Iterator[tuple[float, str, IndexEntry]]:
            for entry in self.index(sid):
                yield entry.t, sid, entry

        for _, sid, entry in heapq.merge(
            *(keyed(s) for s in chosen), key=lambda item: (item[0], item[1])
        ):
            yield self.load(sid, entry, streams)

    def __repr__(self) -> str:
        return f"Recording({str(self.path)!r}, sensors={self.sensor_ids})"
