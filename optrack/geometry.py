"""SE(3) transforms, planes, projection and back-projection.

Poses are 4x4 homogeneous matrices named ``a_T_b``: they map points from
frame ``b`` into frame ``a`` (``p_a = a_T_b @ p_b``), so that
``a_T_c = compose(a_T_b, b_T_c)``. Rotations go through SciPy's
``Rotation``; quaternions are (x, y, z, w) as in SciPy and ROS.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from optrack.errors import UserError
from optrack.types import Intrinsics

__all__ = [
    "Plane",
    "backproject",
    "backproject_points",
    "camera_frustum",
    "compose",
    "floor_footprint",
    "invert",
    "make_pose",
    "pixel_rays",
    "pose_from_quaternion",
    "pose_from_rvec_tvec",
    "pose_to_quaternion",
    "pose_to_rvec_tvec",
    "project",
    "rotation_angle_deg",
    "transform_points",
]


# --------------------------------------------------------------------------- SE(3)


def make_pose(
    rotation: np.ndarray | Rotation | None = None, translation: Sequence[float] = (0, 0, 0)
) -> np.ndarray:
    """A 4x4 pose from a 3x3 rotation matrix (or SciPy Rotation) and a translation."""
    pose = np.eye(4)
    if rotation is not None:
        pose[:3, :3] = rotation.as_matrix() if isinstance(rotation, Rotation) else rotation
    pose[:3, 3] = np.asarray(translation, dtype=np.float64)
    return pose


def compose(*poses: np.ndarray) -> np.ndarray:
    """Chain poses left to right: ``compose(a_T_b, b_T_c) == a_T_c``."""
    out = np.eye(4)
    for pose in poses:
        out = out @ np.asarray(pose, dtype=np.float64)
    return out


def invert(pose: np.ndarray) -> np.ndarray:
    """Inverse of a rigid transform: ``invert(a_T_b) == b_T_a`` (exact, no matrix inverse)."""
    pose = np.asarray(pose, dtype=np.float64)
    rotation_t = pose[:3, :3].T
    out = np.eye(4)
    out[:3, :3] = rotation_t
    out[:3, 3] = -rotation_t @ pose[:3, 3]
    return out


_BY_COLUMNS_FROM = 2000  # points; below it the matrix product is as fast


def transform_points(pose: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply ``a_T_b`` to Nx3 (or ...x3) points in frame b; NaNs stay NaN."""
    points = np.asarray(points)
    pose = np.asarray(pose, dtype=np.float64)
    dtype = np.result_type(points.dtype, np.float32)
    if points.size < 3 * _BY_COLUMNS_FROM:
        out = points @ pose[:3, :3].T + pose[:3, 3]
        return out.astype(dtype, copy=False)
    # By columns, in the points' own precision: an (N, 3) x (3, 3) product goes to BLAS,
    # whose threads spin (a 640x480 cloud: 40 ms of CPU against 2 ms this way).
    flat = points.reshape(-1, 3)
    matrix = np.asarray(pose, dtype=dtype)
    out = np.empty(flat.shape, dtype=dtype)
    x, y, z = flat[:, 0], flat[:, 1], flat[:, 2]
    for i in range(3):
        column = out[:, i]
        np.multiply(x, matrix[i, 0], out=column)
        column += y * matrix[i, 1]
        column += z * matrix[i, 2]
        column += matrix[i, 3]
    return out.reshape(points.shape)


def pose_from_quaternion(
    quaternion_xyzw: Sequence[float], translation: Sequence[float]
) -> np.ndarray:
    """Pose from a quaternion (x, y, z, w) and a translation."""
    return make_pose(Rotation.from_quat(np.asarray(quaternion_xyzw, dtype=np.float64)), translation)


def pose_to_quaternion(pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(quaternion (x, y, z, w) with w >= 0, translation) of a pose."""
    pose = np.asarray(pose, dtype=np.float64)
    quaternion = Rotation.from_matrix(pose[:3, :3]).as_quat()
    if quaternion[3] < 0:
        quaternion = -quaternion
    return quaternion, pose[:3, 3].copy()


def pose_from_rvec_tvec(rvec: Sequence[float], tvec: Sequence[float]) -> np.ndarray:
    """Pose from OpenCV's Rodrigues vector and translation (e.g. ``cv2.solvePnP``)."""
    rotation, _ = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3, 1))
    return make_pose(rotation, np.asarray(tvec, dtype=np.float64).reshape(3))


def pose_to_rvec_tvec(pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV's (rvec, tvec), each of shape (3,), of a pose."""
    pose = np.asarray(pose, dtype=np.float64)
    rvec, _ = cv2.Rodrigues(pose[:3, :3])
    return rvec.reshape(3), pose[:3, 3].copy()


def rotation_angle_deg(a_T_b: np.ndarray, a_T_c: np.ndarray | None = None) -> float:
    """Rotation angle of a pose, or of the relative rotation between two poses, in degrees."""
    rotation = np.asarray(a_T_b, dtype=np.float64)[:3, :3]
    if a_T_c is not None:
        rotation = rotation.T @ np.asarray(a_T_c, dtype=np.float64)[:3, :3]
    return float(np.degrees(Rotation.from_matrix(rotation).magnitude()))


# -------------------------------------------------------------------------- planes


class Plane:
    """The plane ``a x + b y + c z + d = 0`` with unit normal (a, b, c).

    ``distance`` is signed: positive on the side the normal points to. For a
    ground plane, the normal points up (towards the camera's people).
    """

    __slots__ = ("coefficients",)

    def __init__(self, a: float, b: float, c: float, d: float) -> None:
        coefficients = np.array([a, b, c, d], dtype=np.float64)
        norm = np.linalg.norm(coefficients[:3])
        if not np.isfinite(norm) or norm < 1e-12:
            raise ValueError(f"a plane needs a non-zero normal; got ({a}, {b}, {c}, {d}).")
        self.coefficients = coefficients / norm

    # construction ---------------------------------------------------------
    @classmethod
    def from_coefficients(cls, coefficients: Sequence[float]) -> Plane:
        values = [float(v) for v in coefficients]
        if len(values) != 4:
            raise ValueError(f"a plane is four numbers a,b,c,d; got {len(values)}.")
        return cls(*values)

    @classmethod
    def parse(cls, text: str) -> Plane:
        """Parse ``"a,b,c,d"`` as given on the command line."""
        try:
            return cls.from_coefficients([float(p) for p in text.split(",") if p.strip()])
        except ValueError as error:
            raise UserError(
                f"ground plane must be four numbers 'a,b,c,d'; got '{text}' ({error})"
            ) from None

    @classmethod
    def from_point_normal(cls, point: Sequence[float], normal: Sequence[float]) -> Plane:
        normal = np.asarray(normal, dtype=np.float64)
        return cls(*normal, -float(normal @ np.asarray(point, dtype=np.float64)))

    @classmethod
    def from_points(cls, p1: Sequence[float], p2: Sequence[float], p3: Sequence[float]) -> Plane:
        """The plane through three points (normal by the right-hand rule p1->p2->p3)."""
        p1, p2, p3 = (np.asarray(p, dtype=np.float64) for p in (p1, p2, p3))
        normal = np.cross(p2 - p1, p3 - p1)
        if np.linalg.norm(normal) < 1e-9:
            raise ValueError("the three points are on one line; pick points that span a plane.")
        return cls.from_point_normal(p1, normal)

    @classmethod
    def fit(cls, points: np.ndarray) -> Plane:
        """Total-least-squares plane through Nx3 points (NaNs ignored): the normal is
        the direction of least spread, from the 3x3 scatter matrix's eigenvectors rather
        than an SVD of the N points (Hartley and Zisserman A5.2; the same plane in about
        a quarter of the time on the detector's 4000 floor points per frame).

        Use :meth:`segment` when the points contain outliers.
        """
        # 3xN contiguous rows: Nx3 strided reductions cost several times more
        columns = np.asarray(points, dtype=np.float64).reshape(-1, 3).T.copy()
        finite = np.isfinite(columns).all(axis=0)
        if not finite.all():
            columns = columns[:, finite]
        if columns.shape[1] < 3:
            raise ValueError(
                f"fitting a plane needs at least 3 valid points; got {columns.shape[1]}."
            )
        centroid = columns.mean(axis=1)
        centred = columns - centroid[:, None]
        spread, axes = np.linalg.eigh(centred @ centred.T)  # ascending: the normal is first
        # On one line the middle spread vanishes, to the scatter matrix's precision (squared
        # singular values: relative 1e-12 where an SVD resolves 1e-9).
        if spread[1] <= 1e-12 * max(spread[2], 1e-24):
            raise ValueError("the points are on one line; a plane cannot be fitted.")
        return cls.from_point_normal(centroid, axes[:, 0])

    @classmethod
    def segment(
        cls,
        points: np.ndarray,
        distance_threshold: float,
        ransac_n: int = 3,
        iterations: int = 1000,
        seed: int | None = 0,
    ) -> tuple[Plane, np.ndarray]:
        """Robust plane by Open3D's RANSAC: (plane, indices of the inliers in ``points``)."""
        import open3d as o3d

        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        valid = np.flatnonzero(np.all(np.isfinite(points), axis=1))
        if len(valid) < ransac_n:
            raise ValueError(
                f"segmenting a plane needs at least {ransac_n} valid points; got {len(valid)}."
            )
        if seed is not None:
            o3d.utility.random.seed(seed)
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points[valid]))
        model, inliers = cloud.segment_plane(distance_threshold, ransac_n, iterations)
        return cls.from_coefficients(model), valid[np.asarray(inliers, dtype=np.int64)]

    # queries --------------------------------------------------------------
    @property
    def normal(self) -> np.ndarray:
        return self.coefficients[:3].copy()

    @property
    def d(self) -> float:
        return float(self.coefficients[3])

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distances (metres) of ...x3 points; NaN for NaN points."""
        points = np.asarray(points)
        return points @ self.coefficients[:3] + self.coefficients[3]

    def project(self, points: np.ndarray) -> np.ndarray:
        """Orthogonal projection of ...x3 points onto the plane."""
        points = np.asarray(points, dtype=np.float64)
        return points - self.distance(points)[..., None] * self.coefficients[:3]

    def flipped(self) -> Plane:
        return Plane(*(-self.coefficients))

    def oriented_towards(self, point: Sequence[float]) -> Plane:
        """The same plane with its normal pointing to the side of ``point``."""
        return self if self.distance(np.asarray(point, dtype=np.float64)) >= 0 else self.flipped()

    def transform(self, a_T_b: np.ndarray) -> Plane:
        """This plane (given in frame b) expressed in frame a."""
        pose = np.asarray(a_T_b, dtype=np.float64)
        normal = pose[:3, :3] @ self.coefficients[:3]
        return Plane(*normal, self.coefficients[3] - normal @ pose[:3, 3])

    def angle_deg(self, other: Plane) -> float:
        """Angle between the two planes' normals, degrees in [0, 180]."""
        cosine = float(np.clip(self.coefficients[:3] @ other.coefficients[:3], -1.0, 1.0))
        return float(np.degrees(np.arccos(cosine)))

    def offset(self, other: Plane, at: Sequence[float] = (0.0, 0.0, 0.0)) -> float:
        """Distance (metres) from ``at`` projected onto this plane, to ``other``.

        For two near-parallel planes this is how far apart they are near
        ``at`` (the origin by default: for a camera-frame ground plane, under
        the camera).
        """
        foot = self.project(np.asarray(at, dtype=np.float64))
        return float(abs(other.distance(foot)))

    def to_list(self) -> list[float]:
        return [float(v) for v in self.coefficients]

    def __iter__(self):  # noqa: ANN204 - lets a, b, c, d = plane
        return iter(self.to_list())

    def __repr__(self) -> str:
        a, b, c, d = self.coefficients
        return f"Plane({a:.6g}, {b:.6g}, {c:.6g}, {d:.6g})"


# ----------------------------------------------------- projection, back-projection


@functools.lru_cache(maxsize=16)
def pixel_rays(intrinsics: Intrinsics, height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """Normalised image coordinates (x/z, y/z) of every pixel centre, HxW float64 each,
    with lens distortion undone. Cached per camera; the arrays are read-only."""
    u = np.arange(width, dtype=np.float64)
    v = np.arange(height, dtype=np.float64)
    if not intrinsics.has_distortion:
        x = (u - intrinsics.cx) / intrinsics.fx
        y = (v - intrinsics.cy) / intrinsics.fy
        return np.broadcast_to(x, (height, width)), np.broadcast_to(y[:, None], (height, width))
    uu, vv = np.meshgrid(u, v)
    pixels = np.stack([uu.ravel(), vv.ravel()], axis=1).reshape(-1, 1, 2)
    normalised = cv2.undistortPoints(pixels, intrinsics.K, intrinsics.dist_coeffs).reshape(
        height, width, 2
    )
    x_over_z, y_over_z = normalised[..., 0].copy(), normalised[..., 1].copy()
    x_over_z.setflags(write=False)
    y_over_z.setflags(write=False)
    return x_over_z, y_over_z


def backproject(depth_m: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    """Organised cloud (HxWx3 float32, camera frame) from a depth image in metres.

    Invalid pixels (0, negative or NaN depth) give NaN points, as in PCL's
    organised clouds. Distortion, when the intrinsics have it, is undone.
    """
    depth = np.asarray(depth_m)
    if depth.ndim != 2:
        raise ValueError(f"depth must be an HxW image; got shape {depth.shape}.")
    height, width = depth.shape
    z = depth.astype(np.float32, copy=True)
    z[~(z > 0)] = np.nan
    x_over_z, y_over_z = pixel_rays(intrinsics, height, width)
    cloud = np.empty((height, width, 3), dtype=np.float32)
    np.multiply(x_over_z, z, out=cloud[..., 0], casting="unsafe")
    np.multiply(y_over_z, z, out=cloud[..., 1], casting="unsafe")
    cloud[..., 2] = z
    return cloud


def backproject_points(
    depth_m: np.ndarray, intrinsics: Intrinsics, stride: int = 1
) -> tuple[np.ndarray, np.ndarray]:
    """Unorganised cloud: (Nx3 float32 valid points, Nx2 int (row, col) pixel indices).

    ``stride`` subsamples rows and columns (OpenPTrack's sampling factor).
    """
    depth = np.asarray(depth_m)
    if stride < 1:
        raise ValueError(f"stride must be >= 1; got {stride}.")
    rows, cols = np.nonzero(depth[::stride, ::stride] > 0)
    rows *= stride
    cols *= stride
    z = depth[rows, cols].astype(np.float64)
    if intrinsics.has_distortion:
        pixels = np.stack([cols, rows], axis=1).astype(np.float64).reshape(-1, 1, 2)
        normalised = cv2.undistortPoints(pixels, intrinsics.K, intrinsics.dist_coeffs).reshape(
            -1, 2
        )
        x, y = normalised[:, 0] * z, normalised[:, 1] * z
    else:
        x = (cols - intrinsics.cx) * z / intrinsics.fx
        y = (rows - intrinsics.cy) * z / intrinsics.fy
    points = np.stack([x, y, z], axis=1).astype(np.float32)
    return points, np.stack([rows, cols], axis=1)


def project(points: np.ndarray, intrinsics: Intrinsics) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates (Nx2 float, u then v) of Nx3 camera-frame points, and a mask of
    the points in front of the camera (z > 0). Distortion is applied when present."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    in_front = points[:, 2] > 0
    if intrinsics.has_distortion:
        pixels, _ = cv2.projectPoints(
            points, np.zeros(3), np.zeros(3), intrinsics.K, intrinsics.dist_coeffs
        )
        return pixels.reshape(-1, 2), in_front
    with np.errstate(divide="ignore", invalid="ignore"):
        u = intrinsics.fx * points[:, 0] / points[:, 2] + intrinsics.cx
        v = intrinsics.fy * points[:, 1] / points[:, 2] + intrinsics.cy
    return np.stack([u, v], axis=1), in_front


# ------------------------------------------------------- field of view, coverage


def _image_corner_rays(intrinsics: Intrinsics) -> np.ndarray:
    """Rays (x/z, y/z, 1) through the outer corners of the image, 4x3, clockwise in the
    image from the top-left. Corners are at -0.5 and size - 0.5 (pixel centres at integers)."""
    if not (intrinsics.width and intrinsics.height):
        raise ValueError("the field of view needs the intrinsics' image size (width, height).")
    right, bottom = intrinsics.width - 0.5, intrinsics.height - 0.5
    pixels = np.array([[-0.5, -0.5], [right, -0.5], [right, bottom], [-0.5, bottom]])
    if intrinsics.has_distortion:
        normalised = cv2.undistortPoints(
            pixels.reshape(-1, 1, 2), intrinsics.K, intrinsics.dist_coeffs
        ).reshape(-1, 2)
    else:
        normalised = (pixels - (intrinsics.cx, intrinsics.cy)) / (intrinsics.fx, intrinsics.fy)
    return np.column_stack([normalised, np.ones(4)])


def camera_frustum(intrinsics: Intrinsics, world_T_camera: np.ndarray, depth: float) -> np.ndarray:
    """The camera's viewing pyramid up to ``depth`` metres along its optical axis: 5x3
    world points, the optical centre then the four image corners at that depth
    (top-left, top-right, bottom-right, bottom-left as seen in the image)."""
    if not depth > 0:
        raise ValueError(f"frustum depth must be > 0 m; got {depth}.")
    corners = _image_corner_rays(intrinsics) * depth
    points = np.vstack([np.zeros(3), corners])
    return transform_points(world_T_camera, points).astype(np.float64)


def floor_footprint(
    intrinsics: Intrinsics,
    world_T_camera: np.ndarray,
    max_depth: float,
    floor: Plane | None = None,
) -> np.ndarray:
    """Where the camera sees the floor: the section of its viewing pyramid (depth in
    (0, ``max_depth``] metres along the optical axis, as the detector's ``max_distance``)
    by the floor plane (world z = 0 unless given, world frame).

    The pyramid is convex, so the section is a convex polygon: the points where the
    pyramid's eight edges cross the plane, ordered counter-clockwise seen from the
    normal's side. Returns Kx3 world points (K >= 3), or 0x3 when the camera does not
    see the floor within ``max_depth``.
    """
    floor = Plane(0.0, 0.0, 1.0, 0.0) if floor is None else floor
    vertices = camera_frustum(intrinsics, world_T_camera, max_depth)
    edges = [(0, 1), (0, 2), (0, 3), (0, 4), (1, 2), (2, 3), (3, 4), (4, 1)]
    signed = floor.distance(vertices)
    crossings = []
    for i, j in edges:
        di, dj = signed[i], signed[j]
        if di == 0.0:
            crossings.append(vertices[i])
        if (di < 0.0 < dj) or (dj < 0.0 < di):
            crossings.append(vertices[i] + di / (di - dj) * (vertices[j] - vertices[i]))
    if len(crossings) < 3:
        return np.zeros((0, 3))
    points = floor.project(np.unique(np.round(np.array(crossings), 12), axis=0))
    if len(points) < 3:
        return np.zeros((0, 3))
    # Order around the centroid in a 2D basis of the plane.
    normal = floor.normal
    u = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    offsets = points - points.mean(axis=0)
    order = np.argsort(np.arctan2(offsets @ v, offsets @ u))
    return points[order]
