"""Calibration files: one YAML file per network, validated on reading, saved atomically.

::

    format: optrack-calibration
    version: 1
    id: 20250101T120000-3f2a1c      # calibration id
    created: '2025-01-01T12:00:00+00:00'
    board: {cols: 9, rows: 6, square: 0.08, thickness: 0.005}
    world: floor                    # floor | points | camera:<id>
    ground: [0.0, 0.0, 1.0, 0.0]    # the floor in the world frame (z up, origin on it)
    sensors:
      cam0:
        model: kinect2
        image: infrared             # the image the board was found in
        intrinsics: {fx: .., fy: .., cx: .., cy: .., width: .., height: .., dist: [..]}
        world_T_camera: [[..4..], [..], [..], [0, 0, 0, 1]]
        refinement: [[..]]          # correction applied by 'calibrate refine' (identity if none)
        views: 42
        reprojection_rms_px: 0.21
    quality: {reprojection_rms_px: 0.23, views: 120, floor_views: 3}

Saving writes through a temporary file and a rename, after copying the
previous file (if any) to ``<name>.bak``. Reading checks the format name,
the version, every matrix (a rigid transform) and every sensor, and says in
one sentence what is wrong. Exporters write OpenPTrack's
``camera_poses.yaml`` and a list of ROS static transforms.
"""

from __future__ import annotations

import datetime
import os
import secrets
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import msgspec
import numpy as np
import yaml

from optrack.errors import UserError
from optrack.geometry import invert, pose_to_quaternion
from optrack.io.files import atomic_write_bytes, atomic_write_text
from optrack.types import (
    Intrinsics,
    Matrix4,
    NetworkCalibration,
    SensorCalibration,
    as_matrix4,
    pose_problem,
)

if TYPE_CHECKING:
    from optrack.calibration.session import SessionResult

__all__ = [
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "BoardEntry",
    "CalibrationFile",
    "CalibrationFileError",
    "SensorEntry",
    "load_calibration",
    "load_network",
    "new_calibration_id",
    "now_iso",
    "openptrack_camera_poses",
    "ros_static_transforms",
    "save_calibration",
    "session_file",
]

FORMAT_NAME = "optrack-calibration"
FORMAT_VERSION = 1


class CalibrationFileError(UserError):
    """A calibration file that cannot be read, written or used."""


class BoardEntry(msgspec.Struct, forbid_unknown_fields=True):
    cols: int
    rows: int
    square: float
    thickness: float = 0.0


class SensorEntry(msgspec.Struct, forbid_unknown_fields=True, omit_defaults=True):
    """One sensor's calibration. ``world_T_camera`` already includes ``refinement``."""

    world_T_camera: Matrix4
    intrinsics: Intrinsics | None = None
    model: str = ""
    image: str = ""
    refinement: Matrix4 | None = None
    views: int = 0
    reprojection_rms_px: float | None = None

    @property
    def pose(self) -> np.ndarray:
        return np.asarray(self.world_T_camera, dtype=np.float64)


class CalibrationFile(msgspec.Struct, forbid_unknown_fields=True):
    """A network calibration as stored on disk (see the module docstring)."""

    sensors: dict[str, SensorEntry]
    id: str = ""
    created: str = ""
    format: str = FORMAT_NAME
    version: int = FORMAT_VERSION
    board: BoardEntry | None = None
    world: str = "floor"
    ground: tuple[float, float, float, float] = (0.0, 0.0, 1.0, 0.0)
    quality: dict[str, float | int | str | list[str] | None] = {}
    notes: str = ""

    def pose(self, sensor_id: str) -> np.ndarray:
        self.require([sensor_id])
        return self.sensors[sensor_id].pose

    def require(self, sensor_ids: Iterable[str], where: str = "") -> None:
        """Refuse when a sensor is missing (one sentence naming them)."""
        missing = sorted(set(sensor_ids) - set(self.sensors))
        if missing:
            source = f" {where}" if where else ""
            raise CalibrationFileError(
                f"calibration{source} has no sensor {', '.join(repr(m) for m in missing)} "
                f"(it has: {', '.join(sorted(self.sensors)) or 'none'}); calibrate the network "
                "with every sensor or pick the matching file."
            )

    @classmethod
    def from_network(cls, calibration: NetworkCalibration) -> CalibrationFile:
        """A :class:`~optrack.types.NetworkCalibration` (as it travels on the bus) as a file."""
        return cls(
            sensors={
                sid: SensorEntry(
                    world_T_camera=sensor.world_T_camera,
                    intrinsics=sensor.intrinsics,
                    model=sensor.model,
                    reprojection_rms_px=sensor.reprojection_rms_px,
                )
                for sid, sensor in calibration.sensors.items()
            },
            id=calibration.notes or new_calibration_id(),
            created=calibration.created or now_iso(),
            ground=calibration.ground,
        )

    def to_network(self) -> NetworkCalibration:
        """The shared :class:`~optrack.types.NetworkCalibration` the detectors and tracker use."""
        return NetworkCalibration(
            sensors={
                sid: SensorCalibration(
                    world_T_camera=entry.world_T_camera,
                    intrinsics=entry.intrinsics,
                    model=entry.model,
                    reprojection_rms_px=entry.reprojection_rms_px,
                )
                for sid, entry in self.sensors.items()
            },
            ground=self.ground,
            created=self.created,
            notes=self.id,
        )

    @classmethod
    def of_poses(
        cls, world_T_camera: Mapping[str, np.ndarray], infos: Mapping[str, Any], **fields: Any
    ) -> CalibrationFile:
        """A new file (a fresh id, created now) of known poses, e.g. a recording's true ones;
        each sensor's intrinsics and model from ``infos`` (its recorded sensor info)."""
        sensors = {
            sid: SensorEntry(
                world_T_camera=as_matrix4(pose),
                intrinsics=infos[sid].intrinsics,
                model=infos[sid].model,
            )
            for sid, pose in world_T_camera.items()
        }
        return cls(sensors=sensors, id=new_calibration_id(), created=now_iso(), **fields)

    def with_poses(
        self, world_T_camera: Mapping[str, np.ndarray], **fields: object
    ) -> CalibrationFile:
        """A copy with some sensors' poses replaced (other fields kept)."""
        sensors = dict(self.sensors)
        for sid, pose in world_T_camera.items():
            sensors[sid] = msgspec.structs.replace(sensors[sid], world_T_camera=as_matrix4(pose))
        return msgspec.structs.replace(self, sensors=sensors, **fields)

    def with_corrections(
        self, corrections: Mapping[str, np.ndarray], **fields: object
    ) -> CalibrationFile:
        """A copy with each correction (world_T_world, 4x4) applied to its sensor's pose and
        accumulated in the sensor's ``refinement`` (other fields kept)."""
        sensors = dict(self.sensors)
        for sid, correction in corrections.items():
            entry = sensors[sid]
            previous = (
                np.asarray(entry.refinement, dtype=np.float64)
                if entry.refinement is not None
                else np.eye(4)
            )
            sensors[sid] = msgspec.structs.replace(
                entry,
                world_T_camera=as_matrix4(correction @ entry.pose),
                refinement=as_matrix4(correction @ previous),
            )
        return msgspec.structs.replace(self, sensors=sensors, **fields)


def session_file(
    session: SessionResult, models: Mapping[str, str], *, thickness: float, notes: str = ""
) -> CalibrationFile:
    """The calibration file of a calibrated recording: every calibrated sensor (``models``:
    each sensor's model), the board (its face ``thickness`` m above the floor when laid on
    it), the world and the solve's quality."""
    network, board = session.network, session.board
    sensors = {
        sid: SensorEntry(
            world_T_camera=as_matrix4(pose),
            intrinsics=session.intrinsics[sid],
            model=models[sid],
            image=session.image.get(sid, ""),
            views=network.sensors[sid].used_views,
            reprojection_rms_px=network.sensors[sid].rms_px,
        )
        for sid, pose in network.world_T_camera.items()
    }
    return CalibrationFile(
        sensors=sensors,
        id=new_calibration_id(),
        created=now_iso(),
        board=BoardEntry(board.cols, board.rows, board.square, float(thickness)),
        world=network.world,
        quality={
            "reprojection_rms_px": network.rms_px,
            "instants": session.instants,
            "floor_views": network.floor_views,
            "ground": "floor" if network.world == "floor" else "none",
        },
        notes=notes,
    )


def new_calibration_id(now: datetime.datetime | None = None) -> str:
    """A calibration id: the UTC time and a random suffix, e.g. ``20250101T120000-3f2a1c``."""
    now = now or datetime.datetime.now(datetime.UTC)
    return f"{now:%Y%m%dT%H%M%S}-{secrets.token_hex(3)}"


def now_iso() -> str:
    return datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")


# ---------------------------------------------------------------- validation


# how a check's sentence starts and ends: for a file read, and for one about to be written
_READ = "calibration file {path}", "recalibrate, or restore the .bak file"
_WRITE = "the calibration for {path}", "nothing was written; check what it was made from"


def _check_rigid(matrix: object, what: str, where: str, fix: str) -> None:
    problem = pose_problem(np.asarray(matrix, dtype=np.float64))
    if problem is not None:
        raise CalibrationFileError(f"{where}: {what} {problem}; {fix}.")


def _validate(calibration: CalibrationFile, path: Path, wording: tuple[str, str] = _READ) -> None:
    """Refuse what no site has: no sensors, a pose that is not a camera's (not finite, not
    rigid, beyond 1 km), an image of no size, a world that is none of the sensors, a
    ground without a unit normal, a board of no size."""
    where, fix = wording[0].format(path=path), wording[1]
    if not calibration.sensors:
        raise CalibrationFileError(f"{where} lists no sensors; calibrate the network first.")
    for sid, entry in calibration.sensors.items():
        _check_rigid(entry.world_T_camera, f"sensor '{sid}' world_T_camera", where, fix)
        if entry.refinement is not None:
            _check_rigid(entry.refinement, f"sensor '{sid}' refinement", where, fix)
        k = entry.intrinsics
        if k is not None and (k.width < 1 or k.height < 1):
            raise CalibrationFileError(
                f"{where}: sensor '{sid}' intrinsics are for an image of {k.width}x{k.height} "
                f"pixels; width and height must be 1 or more; {fix}."
            )
    world = calibration.world
    camera = world.removeprefix("camera:")
    if world not in ("floor", "points") and (camera == world or camera not in calibration.sensors):
        raise CalibrationFileError(
            f"{where}: world '{world}' must be floor, points or camera:<id> of one of its "
            f"sensors ({', '.join(sorted(calibration.sensors))}); {fix}."
        )
    normal = np.asarray(calibration.ground[:3], dtype=np.float64)
    if not np.all(np.isfinite(calibration.ground)) or not 0.99 < np.linalg.norm(normal) < 1.01:
        raise CalibrationFileError(
            f"{where}: ground must be a plane a,b,c,d with a unit normal; got "
            f"{list(calibration.ground)}."
        )
    board = calibration.board
    if board is not None and not (
        min(board.cols, board.rows) >= 2 and 0 < board.square < 10 and 0 <= board.thickness < 1
    ):
        raise CalibrationFileError(
            f"{where}: board {board.cols}x{board.rows} of {board.square} m squares, "
            f"{board.thickness} m thick, is no checkerboard (at least 2x2 inner corners, squares "
            f"above 0 and below 10 m, a thickness from 0 to below 1 m); {fix}."
        )


def load_calibration(path: str | os.PathLike[str]) -> CalibrationFile:
    """Read and validate a calibration file."""
    path = Path(path)
    if not path.exists():
        raise CalibrationFileError(
            f"calibration file {path} does not exist; run 'optrack calibrate network' to make one."
        )
    if path.is_dir():
        raise CalibrationFileError(f"{path} is a directory, not a calibration file.")
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (yaml.YAMLError, UnicodeDecodeError):
        raise CalibrationFileError(
            f"calibration file {path} is damaged (not valid YAML); restore {path.name}.bak or "
            "calibrate again."
        ) from None
    if not isinstance(data, dict) or data.get("format") != FORMAT_NAME:
        raise CalibrationFileError(
            f"{path} is not an optrack calibration file (it does not say format: {FORMAT_NAME})."
        )
    version = data.get("version")
    if version != FORMAT_VERSION:
        raise CalibrationFileError(
            f"calibration file {path} has version {version}; this optrack reads version "
            f"{FORMAT_VERSION}. Calibrate again with this version."
        )
    try:
        calibration = msgspec.convert(data, CalibrationFile)
    except msgspec.ValidationError as error:
        raise CalibrationFileError(f"calibration file {path} is damaged ({error}).") from None
    except (ValueError, TypeError) as error:  # e.g. intrinsics that fail their own checks
        raise CalibrationFileError(f"calibration file {path} is damaged ({error})") from None
    _validate(calibration, path)
    return calibration


def load_network(path: str | os.PathLike[str]) -> NetworkCalibration:
    """A calibration file as the shared :class:`~optrack.types.NetworkCalibration`."""
    return load_calibration(path).to_network()


def _dump(calibration: CalibrationFile) -> str:
    data = msgspec.to_builtins(calibration)
    ordered = {key: data.pop(key) for key in ("format", "version", "id", "created") if key in data}
    ordered.update(data)
    return yaml.safe_dump(ordered, sort_keys=False, default_flow_style=None, width=120)


def save_calibration(path: str | os.PathLike[str], calibration: CalibrationFile) -> Path | None:
    """Write atomically; an existing file is first copied to ``<name>.bak``.

    Returns the backup's path, or None when there was no previous file.
    """
    path = Path(path)
    _validate(calibration, path, _WRITE)
    if path.is_dir():
        raise CalibrationFileError(
            f"--out {path} is a directory; give a file name such as network.yaml."
        )
    backup = None
    if path.exists():
        backup = path.with_name(path.name + ".bak")
        atomic_write_bytes(backup, path.read_bytes())
    atomic_write_text(path, _dump(calibration))
    return backup


# ------------------------------------------------------------------ exporters


def _pose_block(pose: np.ndarray, indent: str) -> list[str]:
    quaternion, translation = pose_to_quaternion(pose)
    lines = [f"{indent}translation:"]
    lines += [f"{indent}  {k}: {v:.9g}" for k, v in zip("xyz", translation, strict=True)]
    lines += [f"{indent}rotation:"]
    lines += [f"{indent}  {k}: {v:.9g}" for k, v in zip("xyzw", quaternion, strict=True)]
    return lines


def openptrack_camera_poses(calibration: CalibrationFile) -> str:
    """OpenPTrack's ``camera_poses.yaml``: each sensor's pose in the world frame
    (translation and quaternion x, y, z, w) and the inverse poses."""
    created = calibration.created
    try:
        stamp = int(datetime.datetime.fromisoformat(created).timestamp()) if created else 0
    except ValueError:
        stamp = 0
    lines = ["# Auto generated file (optrack).", f"calibration_id: {stamp}", ""]
    lines.append('# Poses w.r.t. the "world" reference frame')
    lines.append("poses:")
    for sid in sorted(calibration.sensors):
        lines.append(f"  {sid}:")
        lines += _pose_block(calibration.sensors[sid].pose, "    ")
    lines += ["", "# Inverse poses", "inverse_poses:"]
    for sid in sorted(calibration.sensors):
        lines.append(f"  {sid}:")
        lines += _pose_block(invert(calibration.sensors[sid].pose), "    ")
    return "\n".join(lines) + "\n"


def ros_static_transforms(calibration: CalibrationFile, parent: str = "world") -> str:
    """The sensors as ROS static transforms (parent ``world``, child the sensor id's
    optical frame), each with the ``static_transform_publisher`` command that publishes it."""
    transforms = []
    for sid in sorted(calibration.sensors):
        quaternion, translation = pose_to_quaternion(calibration.sensors[sid].pose)
        child = f"{sid}_optical_frame"
        args = " ".join(
            f"--{k} {v:.9g}"
            for k, v in zip(
                ("x", "y", "z", "qx", "qy", "qz", "qw"), (*translation, *quaternion), strict=True
            )
        )
        transforms.append(
            {
                "parent": parent,
                "child": child,
                "translation": [round(float(v), 9) for v in translation],
                "rotation_xyzw": [round(float(v), 9) for v in quaternion],
                "command": "ros2 run tf2_ros static_transform_publisher "
                f"{args} --frame-id {parent} --child-frame-id {child}",
            }
        )
    header = "# Static transforms of the optrack calibration " + (calibration.id or "") + "\n"
    return header + yaml.safe_dump({"transforms": transforms}, sort_keys=False, width=200)
