"""Preprocessing: from a frame (or an organised cloud) to a voxelised cloud.

OpenPTrack's ``preprocessCloud`` (Munaro 2012, section 3.1): keep valid
pixels within ``max_distance`` (and, for time-of-flight sensors, above a
confidence), keep every ``sampling_factor``-th pixel in rows and columns,
optionally remove statistical outliers, then a voxel grid. Open3D does the
voxel grid and the outlier removal.
"""

from __future__ import annotations

import functools

import numpy as np
import open3d as o3d

from optrack.detection.kernels import split_stored, voxel_centroids
from optrack.geometry import pixel_rays
from optrack.types import Intrinsics, RGBDFrame

__all__ = ["OrganisedCloud", "denoise", "select_points", "split_at_floor", "voxel_grid"]


class OrganisedCloud:
    """A frame seen as an organised cloud: camera-frame points per pixel, on demand.

    Built either from a depth image (float metres, NaN or 0 invalid; or
    uint16 with ``depth_scale``) and intrinsics, or from an organised HxWx3
    cloud as PCL stores it (NaN invalid). Points are computed only for the
    pixels asked for (strided windows), so that subsampled and cropped uses
    stay cheap.
    """

    def __init__(
        self,
        intrinsics: Intrinsics,
        depth: np.ndarray | None = None,
        depth_scale: float = 1.0,
        points: np.ndarray | None = None,
    ) -> None:
        if (depth is None) == (points is None):
            raise ValueError("give either a depth image or an organised cloud, not both.")
        self.intrinsics = intrinsics
        self._depth = depth
        self._scale = depth_scale
        self._points = points
        if points is not None:
            if points.ndim != 3 or points.shape[2] != 3:
                raise ValueError(f"an organised cloud is HxWx3; got shape {points.shape}.")
            self.shape: tuple[int, int] = points.shape[:2]
        else:
            assert depth is not None
            if depth.ndim != 2:
                raise ValueError(f"a depth image is HxW; got shape {depth.shape}.")
            self.shape = depth.shape  # type: ignore[assignment]

    @classmethod
    def from_frame(cls, frame: RGBDFrame) -> OrganisedCloud:
        return cls(frame.intrinsics, depth=frame.depth, depth_scale=frame.depth_scale)

    @property
    def stored(self) -> bool:
        """True for a stored cloud (x, y, z per pixel), False for a depth image."""
        return self._points is not None

    def z(self, rows: slice, cols: slice) -> np.ndarray:
        """Depth (metres, float32, NaN where invalid) of a strided window of pixels."""
        if self._points is not None:
            return self._points[rows, cols, 2]
        assert self._depth is not None
        raw = self._depth[rows, cols]
        if raw.dtype == np.uint16:
            z = np.multiply(raw, np.float32(self._scale), dtype=np.float32)
            z[raw == 0] = np.nan
            return z
        z = raw.astype(np.float32, copy=True)
        z[~(z > 0)] = np.nan
        return z

    def grid(self, rows: slice, cols: slice) -> np.ndarray:
        """Camera-frame points of a strided window, hxwx3 float64 (NaN where invalid)."""
        if self._points is not None:
            return self._points[rows, cols].astype(np.float64)
        z = self.z(rows, cols).astype(np.float64)
        x_over_z, y_over_z = pixel_rays(self.intrinsics, *self.shape)
        return np.stack([x_over_z[rows, cols] * z, y_over_z[rows, cols] * z, z], axis=-1)

    def components(self, rows: slice, cols: slice) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """x, y and z (hxw float64 each, NaN where invalid) of a strided window: the
        values of :meth:`grid`, without stacking them."""
        if self._points is not None:
            window = self._points[rows, cols]
            return tuple(window[..., k].astype(np.float64) for k in range(3))  # type: ignore[return-value]
        z = self.z(rows, cols).astype(np.float64)
        x_over_z, y_over_z = pixel_rays(self.intrinsics, *self.shape)
        return x_over_z[rows, cols] * z, y_over_z[rows, cols] * z, z

    def xyz(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Camera-frame points (Nx3 float64) of the pixels (rows[i], cols[i])."""
        if self._points is not None:
            return self._points[rows, cols].astype(np.float64)
        z = self.z(slice(None), slice(None))[rows, cols].astype(np.float64)
        x_over_z, y_over_z = pixel_rays(self.intrinsics, *self.shape)
        return np.stack([x_over_z[rows, cols] * z, y_over_z[rows, cols] * z, z], axis=1)


def select_points(
    cloud: OrganisedCloud,
    sampling_factor: int,
    max_distance: float,
    confidence: np.ndarray | None = None,
    confidence_threshold: float = 0,
) -> tuple[np.ndarray, int]:
    """Valid points of every ``sampling_factor``-th pixel in rows and columns
    (Nx3 float32, camera frame), and how many pixels were looked at.

    A pixel is valid with depth in (0, max_distance] and, when a confidence
    image is given, confidence >= ``confidence_threshold``.
    """
    s = int(sampling_factor)
    if s < 1:
        raise ValueError(f"sampling_factor must be >= 1; got {sampling_factor}.")
    window = (slice(None, None, s), slice(None, None, s))
    z = cloud.z(*window)
    keep = (z > 0) & (z <= max_distance)  # NaN compares False
    if confidence is not None and confidence_threshold > 0:
        keep &= confidence[window] >= confidence_threshold
    keep = keep.ravel()
    if cloud.stored:
        stored = cloud._points[window].reshape(-1, 3)  # type: ignore[index]
        points = np.compress(keep, stored, axis=0)
    else:
        depth = np.compress(keep, z.ravel()).astype(np.float64)
        x_over_z, y_over_z = pixel_rays(cloud.intrinsics, *cloud.shape)
        points = np.stack(
            [
                np.compress(keep, x_over_z[window].ravel()) * depth,
                np.compress(keep, y_over_z[window].ravel()) * depth,
                depth,
            ],
            axis=1,
        )
    return np.ascontiguousarray(points, dtype=np.float32), z.size


def split_at_floor(
    cloud: OrganisedCloud,
    sampling_factor: int,
    max_distance: float,
    plane: tuple[float, float, float, float],
    floor_distance: float,
    top: float,
    fit_points: int,
    confidence: np.ndarray | None = None,
    confidence_threshold: float = 0,
) -> tuple[np.ndarray, np.ndarray, int]:
    """:func:`select_points` and floor removal in one pass over a depth image.

    A pixel's height above the floor ``plane`` (a, b, c, d, camera frame) is
    ``z (a x/z + b y/z + c) + d``, so heights come from the depth and the pixel
    rays before any point is made. Returns the points higher than
    ``floor_distance`` and lower than ``top`` (Nx3 float32, camera frame), up to
    ``fit_points`` floor points (within ``floor_distance``) evenly spread, and
    how many floor points there were.
    """
    s = int(sampling_factor)
    if s < 1:
        raise ValueError(f"sampling_factor must be >= 1; got {sampling_factor}.")
    if cloud.stored and (confidence is None or confidence_threshold <= 0):
        points, floor_points = split_stored(
            cloud._points, s, max_distance, np.asarray(plane, dtype=np.float64), floor_distance, top
        )
        step = max(1, len(floor_points) // fit_points)
        return points, floor_points[::step], len(floor_points)
    if cloud.stored:
        points, _ = select_points(cloud, s, max_distance, confidence, confidence_threshold)
        a, b, c, d = (np.float32(v) for v in plane)
        heights = points[:, 0] * a + points[:, 1] * b + points[:, 2] * c + d
        floor = np.flatnonzero(np.abs(heights) < floor_distance)
        step = max(1, len(floor) // fit_points)
        above = (heights > floor_distance) & (heights < top)
        return np.compress(above, points, axis=0), points[floor[::step]], len(floor)
    window = (slice(None, None, s), slice(None, None, s))
    z = cloud.z(*window)
    x_over_z, y_over_z = _window_rays(cloud.intrinsics, cloud.shape, s)
    a, b, c, d = plane
    if cloud.intrinsics.has_distortion:
        ray = x_over_z * a + y_over_z * b
    else:  # x/z is the same down a column and y/z along a row: the same sums, broadcast
        ray = x_over_z[:1] * a + y_over_z[:, :1] * b
    ray += c
    with np.errstate(invalid="ignore"):
        heights = z * ray.astype(np.float32)
        heights += np.float32(d)
        keep = z <= max_distance  # NaN (no depth) compares False
        if confidence is not None and confidence_threshold > 0:
            keep &= confidence[window] >= confidence_threshold
        above = heights > floor_distance
        above &= heights < top
        above &= keep
        floor = np.abs(heights) < floor_distance
        floor &= keep

    def points_at(pixels: np.ndarray) -> np.ndarray:
        """Points (Nx3 float32) of a mask of the window, or of flat indices into it."""
        depth = z.ravel()[pixels] if pixels.ndim == 1 else z[pixels]
        points = np.empty((len(depth), 3), dtype=np.float32)
        for k, ray in enumerate((x_over_z, y_over_z)):
            np.multiply(
                ray.ravel()[pixels] if pixels.ndim == 1 else ray[pixels],
                depth,
                out=points[:, k],
                casting="same_kind",
            )
        points[:, 2] = depth
        return points

    floor_pixels = np.flatnonzero(floor)
    step = max(1, len(floor_pixels) // fit_points)
    return points_at(above), points_at(floor_pixels[::step]), len(floor_pixels)


@functools.lru_cache(maxsize=16)
def _window_rays(
    intrinsics: Intrinsics, shape: tuple[int, int], s: int
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`~optrack.geometry.pixel_rays` of every ``s``-th pixel in rows and columns,
    contiguous (read-only, kept per sensor): masks pick from them in one pass."""
    x_over_z, y_over_z = pixel_rays(intrinsics, *shape)
    window = (slice(None, None, s), slice(None, None, s))
    rays = tuple(np.ascontiguousarray(r[window]) for r in (x_over_z, y_over_z))
    for r in rays:
        r.setflags(write=False)
    return rays  # type: ignore[return-value]


def voxel_grid(points: np.ndarray, voxel_size: float, skip: np.ndarray | None = None) -> np.ndarray:
    """Centroid of the points (but those ``skip`` marks) in each occupied voxel (Open3D's
    voxels, in the order of each voxel's first point:
    :func:`~optrack.detection.kernels.voxel_centroids`), Mx3 float64."""
    if points.dtype not in (np.float32, np.float64):
        points = points.astype(np.float64)
    if skip is not None and not len(points):
        skip = None
    return voxel_centroids(np.ascontiguousarray(points).reshape(-1, 3), float(voxel_size), skip)


def denoise(points: np.ndarray, mean_k: int, std_dev: float) -> np.ndarray:
    """Drop statistical outliers (PCL's StatisticalOutlierRemoval, through Open3D)."""
    if len(points) <= mean_k:
        return points
    cloud = o3d.geometry.PointCloud(
        o3d.utility.Vector3dVector(np.ascontiguousarray(points, dtype=np.float64))
    )
    _, kept = cloud.remove_statistical_outlier(int(mean_k), float(std_dev))
    return points[np.asarray(kept, dtype=np.int64)]
