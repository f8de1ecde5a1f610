"""Write recordings frame by frame (constant memory, crash-safe index)."""

from __future__ import annotations

import contextlib
import datetime
import os
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any

import cv2
import msgspec
import numpy as np
import yaml

try:
    import fcntl
except ImportError:  # Windows: one writer per folder is then the caller's care
    fcntl = None  # type: ignore[assignment]

from optrack.io.files import atomic_write_text
from optrack.params import Params
from optrack.recording.format import (
    FORMAT_NAME,
    FORMAT_VERSION,
    GROUND_TRUTH,
    INDEX,
    MANIFEST,
    RECORDING_PARAMS,
    SENSOR_ID,
    SENSORS_DIR,
    GroundTruth,
    IndexEntry,
    Manifest,
    RecordingError,
    SensorInfo,
)
from optrack.types import RGBDFrame

__all__ = ["RecordingWriter"]

_encoder = msgspec.json.Encoder()


class _SensorStream:
    def __init__(self, root: Path, info: SensorInfo) -> None:
        self.info = info
        self.root = root / SENSORS_DIR / info.id
        self.root.mkdir(parents=True, exist_ok=True)
        self.index = (self.root / INDEX).open("ab")
        self.count = 0
        self.bytes = 0
        self.last_t = -float("inf")


class RecordingWriter:
    """Writes a session directory (see :mod:`optrack.recording.format`).

    ``with RecordingWriter(out, sensors) as w: w.write(frame)``. The output
    directory must be new or empty: nothing already there is overwritten.

    ``join=True`` adds these sensors to the recording being written at ``path``
    by other writers (one take of a site: each detector node writes its own
    sensor into the same directory); the directory may hold other sensors but
    not these, and the manifest, rewritten atomically under a lock, lists every
    sensor that joined and, once each writer closes, its frame count.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        sensors: Iterable[SensorInfo],
        *,
        ground_truth: bool = False,
        source: str = "",
        extra: Mapping[str, Any] | None = None,
        params: Params | None = None,
        join: bool = False,
    ) -> None:
        self.path = Path(path)
        self.params = params if params is not None else RECORDING_PARAMS.create()
        self._join = join
        if join and ground_truth:
            raise RecordingError("a joined recording cannot hold ground truth.")
        if join and self.path.exists() and not self.path.is_dir():
            raise RecordingError(
                f"{self.path} is a file, not a recording directory; choose a folder."
            )
        if not join and (
            self.path.exists() and (not self.path.is_dir() or any(self.path.iterdir()))
        ):
            raise RecordingError(
                f"{self.path} already exists and is not an empty directory; choose a new output "
                "directory (nothing was overwritten)."
            )
        sensors = list(sensors)
        if not sensors:
            raise RecordingError("a recording needs at least one sensor.")
        seen: set[str] = set()
        for info in sensors:
            if not SENSOR_ID.match(info.id):
                raise RecordingError(
                    f"sensor id '{info.id}' cannot name a folder; use letters, digits, '_', '-' or '.'."
                )
            if info.id in seen:
                raise RecordingError(
                    f"sensor id '{info.id}' is given twice; sensor ids must be unique."
                )
            seen.add(info.id)
        self.path.mkdir(parents=True, exist_ok=True)
        self._manifest = Manifest(
            format=FORMAT_NAME,
            version=FORMAT_VERSION,
            sensors=sensors,
            created=datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
            source=source,
            ground_truth=ground_truth,
            extra=dict(extra or {}),
        )
        if join:
            self._merge_manifest(new=True)
        else:
            self._write_manifest()
        self._streams = {info.id: _SensorStream(self.path, info) for info in sensors}
        self._truth = (self.path / GROUND_TRUTH).open("ab") if ground_truth else None
        self._truth_t = -float("inf")
        self._truth_count = 0
        self._closed = False

    # -------------------------------------------------------------- public
    @property
    def frame_counts(self) -> dict[str, int]:
        return {sid: stream.count for sid, stream in self._streams.items()}

    @property
    def byte_counts(self) -> dict[str, int]:
        """Bytes of image files written so far, per sensor."""
        return {sid: stream.bytes for sid, stream in self._streams.items()}

    def write(self, frame: RGBDFrame) -> None:
        """Append one frame of a declared sensor; its timestamp must not go back in time."""
        self._check_open()
        stream = self._streams.get(frame.sensor_id)
        if stream is None:
            raise RecordingError(
                f"frame from sensor '{frame.sensor_id}', which this recording does not declare "
                f"(it has: {', '.join(self._streams)})."
            )
        if frame.timestamp < stream.last_t:
            raise RecordingError(
                f"sensor '{frame.sensor_id}' frame at t={frame.timestamp:.6f} s is older than the "
                f"previous one (t={stream.last_t:.6f} s); frames must arrive in time order."
            )
        seq = stream.count
        name = f"{seq:08d}"
        entry: dict[str, Any] = {"seq": seq, "t": float(frame.timestamp)}
        entry["depth"] = self._write_image(stream, "depth", name, frame.depth_mm(), ".png")
        if frame.color is not None:
            ext = "." + str(self.params.color_format)
            bgr = cv2.cvtColor(np.ascontiguousarray(frame.color), cv2.COLOR_RGB2BGR)
            entry["color"] = self._write_image(stream, "color", name, bgr, ext)
        for kind in ("infrared", "confidence"):
            image = getattr(frame, kind)
            if image is not None:
                if image.dtype not in (np.uint8, np.uint16):
                    raise RecordingError(
                        f"sensor '{frame.sensor_id}' {kind} image is {image.dtype}; recordings "
                        "store 8- or 16-bit images, so scale it first."
                    )
                entry[kind] = self._write_image(stream, kind, name, image, ".png")
        stream.index.write(_encoder.encode(IndexEntry(**entry)) + b"\n")
        stream.index.flush()
        stream.count += 1
        stream.last_t = frame.timestamp

    def write_ground_truth(self, truth: GroundTruth) -> None:
        """Append the true state at one instant (time order)."""
        self._check_open()
        if self._truth is None:
            raise RecordingError("this recording was opened without ground_truth=True.")
        if truth.t < self._truth_t:
            raise RecordingError(
                f"ground truth at t={truth.t:.6f} s is older than the previous one "
                f"(t={self._truth_t:.6f} s); write it in time order."
            )
        self._truth.write(_encoder.encode(truth) + b"\n")
        self._truth.flush()
        self._truth_t = truth.t
        self._truth_count += 1

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        handles = [s.index for s in self._streams.values()]
        if self._truth is not None:
            handles.append(self._truth)
        for handle in handles:
            handle.flush()
            os.fsync(handle.fileno())
            handle.close()
        self._manifest.extra["frames"] = self.frame_counts
        if self._truth is not None:
            self._manifest.extra["ground_truth_instants"] = self._truth_count
        if self._join:
            self._merge_manifest(new=False)
        else:
            self._write_manifest()

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------- private
    def _check_open(self) -> None:
        if self._closed:
            raise RecordingError(f"the recording {self.path} is closed.")

    def _write_manifest(self) -> None:
        data = msgspec.to_builtins(self._manifest)
        atomic_write_text(self.path / MANIFEST, yaml.safe_dump(data, sort_keys=False))

    def _merge_manifest(self, new: bool) -> None:
        """join: add this writer's sensors (``new``) or frame counts to the shared manifest."""
        mine = {info.id: info for info in self._manifest.sensors}
        with _locked(self.path / ".manifest.lock"):
            shared = self._manifest
            if (self.path / MANIFEST).is_file():
                data = yaml.safe_load((self.path / MANIFEST).read_text(encoding="utf-8"))
                try:
                    shared = msgspec.convert(data, Manifest)
                except msgspec.ValidationError as error:
                    raise RecordingError(f"{self.path / MANIFEST} is damaged ({error}).") from None
                if shared.format != FORMAT_NAME or shared.version != FORMAT_VERSION:
                    raise RecordingError(
                        f"{self.path} holds another kind of recording; choose a new folder."
                    )
                if new:
                    taken = sorted(set(mine) & {s.id for s in shared.sensors})
                    if taken:
                        raise RecordingError(
                            f"{self.path} already holds a recording of sensor '{taken[0]}'; "
                            "choose a new folder (nothing was overwritten)."
                        )
                    shared.sensors.extend(mine.values())
            for sid in mine if new else ():
                if (self.path / SENSORS_DIR / sid).exists():
                    raise RecordingError(
                        f"{self.path} already holds frames of sensor '{sid}'; choose a new "
                        "folder (nothing was overwritten)."
                    )
            if not new:
                frames = dict(shared.extra.get("frames") or {})  # type: ignore[call-overload]
                frames.update(self.frame_counts)
                shared.extra["frames"] = frames
            data = msgspec.to_builtins(shared)
            atomic_write_text(self.path / MANIFEST, yaml.safe_dump(data, sort_keys=False))

    def _write_image(
        self, stream: _SensorStream, kind: str, name: str, image: np.ndarray, ext: str
    ) -> str:
        if ext == ".jpg":
            flags = [cv2.IMWRITE_JPEG_QUALITY, int(self.params.jpeg_quality)]
        else:
            flags = [cv2.IMWRITE_PNG_COMPRESSION, int(self.params.png_compression)]
        ok, encoded = cv2.imencode(ext, image, flags)
        if not ok:
            raise RecordingError(
                f"OpenCV could not encode the {kind} image of sensor '{stream.info.id}'."
            )
        relative = f"{kind}/{name}{ext}"
        folder = stream.root / kind
        folder.mkdir(exist_ok=True)
        target = stream.root / relative
        tmp = folder / f".{name}{ext}.tmp"
        tmp.write_bytes(encoded.tobytes())
        os.replace(tmp, target)
        stream.bytes += int(encoded.nbytes)
        return relative


@contextlib.contextmanager
def _locked(path: Path) -> Iterator[None]:
    """An exclusive advisory lock on ``path`` (several writers of one joined recording)."""
    with path.open("a") as handle:
        if fcntl is not None:
            fcntl.flock(handle.fileno(), fcntl.LOCK_EX)
        try:
            yield
        finally:
            if fcntl is not None:
                fcntl.flock(handle.fileno(), fcntl.LOCK_UN)
