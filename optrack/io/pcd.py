"""PCD point clouds (PCL's format): read with Open3D, write organised clouds.

Reading goes through Open3D's tensor reader, which handles ``ascii``,
``binary`` and ``binary_compressed`` (LZF) data and ``rgb`` / ``rgba``
colour fields; the header is read here for what Open3D does not keep (the
organisation WIDTH x HEIGHT and the viewpoint). Writing produces PCL's
``binary`` encoding with WIDTH and HEIGHT kept, which Open3D cannot do.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numpy as np

from optrack.errors import UserError
from optrack.io.files import atomic_write_bytes

__all__ = ["PCDError", "PointCloudData", "read_pcd", "read_pcd_header", "write_pcd"]


class PCDError(UserError):
    """A PCD file that cannot be read or written."""


@dataclasses.dataclass
class PointCloudData:
    """A cloud as read from a file.

    ``points`` is HxWx3 float32 for an organised cloud (NaN where invalid),
    Nx3 otherwise; ``colors`` (RGB uint8) has the same leading shape or is
    None. ``viewpoint`` is the sensor pose (tx, ty, tz, qw, qx, qy, qz).
    """

    points: np.ndarray
    colors: np.ndarray | None
    width: int
    height: int
    viewpoint: tuple[float, ...] = (0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)
    data: str = "binary"
    fields: tuple[str, ...] = ("x", "y", "z")

    @property
    def organized(self) -> bool:
        return self.height > 1

    def valid_points(self) -> np.ndarray:
        """Nx3 finite points (organisation dropped)."""
        flat = self.points.reshape(-1, 3)
        return flat[np.all(np.isfinite(flat), axis=1)]


def read_pcd_header(path: str | os.PathLike[str]) -> dict[str, str]:
    """The header of a PCD file as a mapping of keyword to the rest of its line."""
    return _read_header(Path(path))[0]


def _read_header(path: Path) -> tuple[dict[str, str], int]:
    """The header (see :func:`read_pcd_header`) and the offset of the data after it."""
    header: dict[str, str] = {}
    offset = 0
    try:
        with path.open("rb") as handle:
            for _ in range(64):
                raw = handle.readline(4096)
                if not raw:
                    break
                offset += len(raw)
                line = raw.decode("ascii", errors="replace").strip()
                if not line or line.startswith("#"):
                    continue
                key, _, rest = line.partition(" ")
                header[key.upper()] = rest.strip()
                if key.upper() == "DATA":
                    break
    except FileNotFoundError:
        raise PCDError(f"point cloud {path} does not exist; check the path.") from None
    except IsADirectoryError:
        raise PCDError(f"point cloud {path} is a directory, not a .pcd file.") from None
    required = ("FIELDS", "WIDTH", "HEIGHT", "DATA")
    missing = [key for key in required if key not in header]
    if missing:
        raise PCDError(
            f"{path} is not a PCD file (its header lacks {', '.join(missing)}); "
            "give a point cloud saved by PCL, Open3D or optrack."
        )
    return header, offset


# The most one byte of LZF data can stand for: a back reference of 3 bytes repeats at
# most 264 bytes.
LZF_MAX_RATIO = 88


def _check_size(path: Path, header: dict[str, str], offset: int, points: int) -> None:
    """Refuse a header that promises more points than the file's size can hold, before
    anything is allocated for them (Open3D allocates what the header says)."""
    try:
        sizes = [int(v) for v in header.get("SIZE", "").split()]
        counts = [int(v) for v in header.get("COUNT", "").split()] or [1] * len(sizes)
    except ValueError:
        sizes, counts = [], []
    fields = header["FIELDS"].split()
    if len(sizes) != len(fields) or len(counts) != len(fields) or min(sizes + counts) < 1:
        raise PCDError(f"{path} has a malformed SIZE/COUNT in its header (one per field).")
    record = sum(size * count for size, count in zip(sizes, counts, strict=True))
    data = path.stat().st_size - offset
    kind = header["DATA"].lower()
    if kind == "binary_compressed":
        with path.open("rb") as handle:
            handle.seek(offset)
            lengths = np.frombuffer(handle.read(8).ljust(8, b"\0"), dtype="<u4")
        packed, unpacked = int(lengths[0]), int(lengths[1])
        fits = unpacked == points * record and packed <= data - 8
        fits = fits and unpacked <= packed * LZF_MAX_RATIO
    else:  # binary: the records; ascii: at least a digit and a separator per value
        fits = data >= points * (record if kind == "binary" else 2 * sum(counts))
    if not fits:
        raise PCDError(
            f"{path} is damaged: its header promises {points} points but the file holds "
            f"{data} bytes of {kind} data, too few for them."
        )


def read_pcd(path: str | os.PathLike[str]) -> PointCloudData:
    """Read a PCD file: organised clouds come back HxWx3, others Nx3."""
    import open3d as o3d

    path = Path(path)
    header, offset = _read_header(path)
    try:
        width, height = int(header["WIDTH"]), int(header["HEIGHT"])
    except ValueError:
        width = height = -1
    if width < 0 or height < 0:
        raise PCDError(
            f"{path} has a malformed WIDTH/HEIGHT in its header (whole numbers, 0 or more)."
        )
    fields = tuple(header["FIELDS"].split())
    if not {"x", "y", "z"} <= set(fields):
        raise PCDError(
            f"{path} has no x y z fields (it has {' '.join(fields)}); it is not a point cloud optrack can use."
        )
    data = header["DATA"].lower()
    if data not in ("ascii", "binary", "binary_compressed"):
        raise PCDError(
            f"{path} uses DATA {data}; PCD data must be ascii, binary or binary_compressed."
        )
    expected = width * height
    _check_size(path, header, offset, expected)
    cloud = o3d.t.io.read_point_cloud(
        str(path), remove_nan_points=False, remove_infinite_points=False
    )
    if "positions" not in cloud.point or len(cloud.point.positions) != expected:
        got = len(cloud.point.positions) if "positions" in cloud.point else 0
        raise PCDError(
            f"{path} is damaged: its header promises {expected} points but {got} could be read."
        )
    points = cloud.point.positions.numpy().astype(np.float32, copy=False)
    colors = None
    if "colors" in cloud.point and ({"rgb", "rgba"} & set(fields)):
        colors = cloud.point.colors.numpy()
        if colors.dtype != np.uint8:
            colors = np.clip(np.rint(colors * 255.0), 0, 255).astype(np.uint8)
    if height > 1:
        points = points.reshape(height, width, 3)
        if colors is not None:
            colors = colors.reshape(height, width, 3)
    viewpoint = _viewpoint(path, header.get("VIEWPOINT", "0 0 0 1 0 0 0"))
    return PointCloudData(points, colors, width, height, viewpoint, data, fields)


def _viewpoint(path: Path, text: str) -> tuple[float, ...]:
    """The header's VIEWPOINT: seven finite numbers tx ty tz qw qx qy qz."""
    try:
        values = tuple(float(v) for v in text.split())
    except ValueError:
        values = ()
    if len(values) != 7 or not np.all(np.isfinite(values)):
        raise PCDError(
            f"{path} has a malformed VIEWPOINT '{text}' in its header; it must be seven finite "
            "numbers tx ty tz qw qx qy qz."
        )
    return values


def write_pcd(
    path: str | os.PathLike[str],
    points: np.ndarray,
    colors: np.ndarray | None = None,
    viewpoint: tuple[float, ...] = (0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0),
) -> None:
    """Write a binary PCD (PCL 0.7). HxWx3 points stay organised (NaN kept).

    Colours (RGB uint8, same leading shape) go into PCL's packed ``rgb``
    field. The file appears atomically.
    """
    points = np.asarray(points, dtype=np.float32)
    if points.ndim == 3 and points.shape[2] == 3:
        height, width = points.shape[:2]
    elif points.ndim == 2 and points.shape[1] == 3:
        height, width = 1, points.shape[0]
    else:
        raise PCDError(f"points must be Nx3 or HxWx3; got shape {points.shape}.")
    flat = points.reshape(-1, 3)
    if colors is not None:
        colors = np.asarray(colors)
        if (
            colors.shape[:-1] != points.shape[:-1]
            or colors.shape[-1] != 3
            or colors.dtype != np.uint8
        ):
            raise PCDError(
                f"colors must be uint8 RGB with the points' shape {points.shape}; got {colors.shape} {colors.dtype}."
            )
        record = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgb", "<u4")])
        rgb = colors.reshape(-1, 3).astype(np.uint32)
        packed = (rgb[:, 0] << 16) | (rgb[:, 1] << 8) | rgb[:, 2]
        body = np.empty(len(flat), dtype=record)
        body["rgb"] = packed
        fields, sizes, types = "x y z rgb", "4 4 4 4", "F F F F"
    else:
        record = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
        body = np.empty(len(flat), dtype=record)
        fields, sizes, types = "x y z", "4 4 4", "F F F"
    body["x"], body["y"], body["z"] = flat[:, 0], flat[:, 1], flat[:, 2]
    counts = " ".join("1" for _ in fields.split())
    header = (
        "# .PCD v0.7 - Point Cloud Data file format\n"
        "VERSION 0.7\n"
        f"FIELDS {fields}\nSIZE {sizes}\nTYPE {types}\nCOUNT {counts}\n"
        f"WIDTH {width}\nHEIGHT {height}\n"
        f"VIEWPOINT {' '.join(f'{v:g}' for v in viewpoint)}\n"
        f"POINTS {width * height}\nDATA binary\n"
    )
    atomic_write_bytes(path, header.encode("ascii") + body.tobytes())
