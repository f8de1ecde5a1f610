"""The ground plane of one sensor, in its camera frame.

Every plane here is a :class:`~optrack.geometry.Plane` whose normal points
up, towards the camera, so that its ``d`` is the camera's height above the
floor and ``distance`` is a height. Ways to get one (OpenPTrack's
``GroundplaneEstimation``, Munaro et al. 2016 section 4.1):

* automatic: segment planes with Open3D's RANSAC, keep those near the
  camera's down direction and below it, take the lowest large one;
* manual: three points, in metres or in pixels of an organised cloud;
* semi-automatic: the segmented plane nearest to a point the operator picks;
* from calibration: the world's z = 0 seen from the camera;
* OpenPTrack's combination of the last with the cloud's own plane.

:class:`GroundEstimator` keeps one sensor's plane across frames and refits it
to each frame's floor points unless locked; :class:`GroundStore` saves and
loads planes per sensor.
"""

from __future__ import annotations

import dataclasses
import datetime
import math
import os
import re
from collections.abc import Sequence
from pathlib import Path

import msgspec
import numpy as np
import open3d as o3d

from optrack.errors import UserError
from optrack.geometry import Plane, invert
from optrack.io.files import atomic_write_bytes
from optrack.params import Params

__all__ = [
    "GroundError",
    "GroundEstimator",
    "GroundStore",
    "PlaneCandidate",
    "automatic_ground",
    "check_ground",
    "combine_with_calibration",
    "ground_from_calibration",
    "ground_from_pixels",
    "ground_from_points",
    "ground_T_camera",
    "parse_ground",
    "refine_ground",
    "segment_planes",
    "semi_automatic_ground",
]

#: The camera's down direction in its own (OpenCV) frame.
CAMERA_DOWN = np.array([0.0, 1.0, 0.0])
#: Nearer than this (metres) the camera counts as lying on the plane.
MIN_CAMERA_HEIGHT = 1e-3
#: Floor points a per-frame refit uses at most (a least-squares plane through a few
#: thousand points is as good as through all, and far cheaper).
FIT_POINTS = 4000


class GroundError(UserError):
    """A ground plane that cannot be used."""


def check_ground(plane: Plane | Sequence[float], what: str | None = None) -> Plane:
    """A usable ground plane, oriented towards the camera, or a :class:`GroundError`.

    ``what`` names the plane in messages (default: "the ground plane [a, b, c, d]").
    """
    try:
        coefficients = [float(v) for v in plane]  # type: ignore[union-attr]
    except (TypeError, ValueError):
        raise GroundError(
            f"{what or 'the ground plane'} must be four numbers a,b,c,d; got {plane!r}."
        ) from None
    what = what or f"the ground plane {coefficients}"
    if len(coefficients) != 4 or not all(math.isfinite(v) for v in coefficients):
        raise GroundError(
            f"{what} must be four finite numbers a,b,c,d (a x + b y + c z + d = 0, camera frame)."
        )
    try:
        result = Plane(*coefficients)
    except ValueError:
        raise GroundError(
            f"{what} is not a plane: its normal (a, b, c) is zero; give a,b,c,d with a "
            "non-zero normal, e.g. 0,-1,0,1.2 for a floor 1.2 m below a level camera."
        ) from None
    if abs(result.d) < MIN_CAMERA_HEIGHT:
        raise GroundError(
            f"{what} passes through the camera (d = 0), so it cannot be the floor under it; "
            "check the plane's d (the camera's height, metres)."
        )
    return result.oriented_towards((0.0, 0.0, 0.0))


def parse_ground(text: str) -> Plane:
    """A ground plane from ``"a,b,c,d"`` (the command line's ``--ground``)."""
    parts = [p for p in re.split(r"[,\s]+", text.strip()) if p]
    try:
        values = [float(p) for p in parts]
    except ValueError:
        raise GroundError(
            f"--ground must be four numbers a,b,c,d (camera frame); got '{text}'."
        ) from None
    return check_ground(values, f"--ground '{text}'")


def ground_T_camera(plane: Plane) -> np.ndarray:
    """The ground frame of a camera, as a 4x4 ``ground_T_camera``.

    z along the plane's normal (up), x along the camera's x projected on
    the floor (the camera's z when the camera looks straight down its x),
    origin on the floor under the camera. Heights are z; a person's floor
    position is (x, y).
    """
    n = plane.normal
    for axis in (np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])):
        x = axis - n * (axis @ n)
        norm = np.linalg.norm(x)
        if norm > 0.1:
            break
    x /= norm
    y = np.cross(n, x)
    rotation = np.stack([x, y, n])
    foot = -plane.d * n  # the camera's origin dropped onto the plane
    pose = np.eye(4)
    pose[:3, :3] = rotation
    pose[:3, 3] = -rotation @ foot
    return pose


def ground_from_points(p1: Sequence[float], p2: Sequence[float], p3: Sequence[float]) -> Plane:
    """Manual ground: the plane through three floor points (camera frame, metres)."""
    points = np.asarray([p1, p2, p3], dtype=np.float64)
    if points.shape != (3, 3) or not np.all(np.isfinite(points)):
        raise GroundError(
            "manual ground needs three floor points with finite x, y, z (metres, camera frame)."
        )
    try:
        plane = Plane.from_points(*points)
    except ValueError:
        raise GroundError(
            "the three floor points are on one line, so they do not define the floor; "
            "pick three points spread over the floor."
        ) from None
    return check_ground(plane, "the plane through the three floor points")


def ground_from_pixels(cloud: object, pixels: Sequence[tuple[int, int]]) -> Plane:
    """Manual ground from three pixels ``(u, v)`` of an organised cloud
    (:class:`~optrack.detection.preprocessing.OrganisedCloud`)."""
    if len(pixels) != 3:
        raise GroundError(f"manual ground needs three floor pixels; got {len(pixels)}.")
    height, width = cloud.shape  # type: ignore[attr-defined]
    rows, cols = [], []
    for u, v in pixels:
        if not (0 <= u < width and 0 <= v < height):
            raise GroundError(
                f"floor pixel ({u}, {v}) is outside the {width}x{height} image; pick pixels inside it."
            )
        rows.append(int(v))
        cols.append(int(u))
    points = cloud.xyz(np.array(rows), np.array(cols))  # type: ignore[attr-defined]
    bad = [pixels[i] for i in range(3) if not np.all(np.isfinite(points[i]))]
    if bad:
        raise GroundError(
            f"floor pixel(s) {', '.join(map(str, bad))} have no depth; pick floor pixels the sensor sees."
        )
    return ground_from_points(*points)


def ground_from_calibration(world_T_camera: np.ndarray) -> Plane:
    """The world's floor (z = 0) in the camera frame."""
    return check_ground(
        Plane(0.0, 0.0, 1.0, 0.0).transform(invert(world_T_camera)),
        "the calibration's floor",
    )


@dataclasses.dataclass
class PlaneCandidate:
    """A plane segmented from the cloud: the plane (normal towards the camera) and
    its inlier points (camera frame)."""

    plane: Plane
    points: np.ndarray

    @property
    def inliers(self) -> int:
        return len(self.points)

    @property
    def centroid(self) -> np.ndarray:
        return self.points.mean(axis=0)


def segment_planes(points: np.ndarray, params: Params, seed: int = 0) -> list[PlaneCandidate]:
    """Up to ``ground_max_planes`` planes, largest first, by repeated RANSAC (Open3D)."""
    o3d.utility.random.seed(seed)
    rest = np.asarray(points, dtype=np.float64)
    threshold = float(params.ground_segment_distance)
    found: list[PlaneCandidate] = []
    for _ in range(int(params.ground_max_planes)):
        if len(rest) < int(params.ground_min_plane_points):
            break
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(rest))
        model, inliers = cloud.segment_plane(threshold, 3, int(params.ground_ransac_iterations))
        inliers = np.asarray(inliers, dtype=np.int64)
        if len(inliers) < int(params.ground_min_plane_points):
            break
        try:
            plane = Plane(*model)
        except ValueError:
            break
        if abs(plane.d) >= MIN_CAMERA_HEIGHT:
            plane = plane.oriented_towards((0.0, 0.0, 0.0))
            found.append(PlaneCandidate(plane, rest[inliers]))
        rest = np.delete(rest, inliers, axis=0)
    return found


def refine_ground(plane: Plane, points: np.ndarray, params: Params) -> tuple[Plane, bool]:
    """Least-squares refits of ``plane`` to the points within ``ground_inlier_distance``
    (OpenPTrack's ``refineGround``); stops when too few points support it.

    Returns the plane and whether it was refitted at least once.
    """
    updated = False
    minimum = update_min_points(params)
    for _ in range(int(params.ground_refine_iterations)):
        inliers = np.abs(plane.distance(points)) < float(params.ground_inlier_distance)
        if np.count_nonzero(inliers) < max(minimum, 3):
            break
        try:
            refit = Plane.fit(points[inliers]).oriented_towards((0.0, 0.0, 0.0))
        except ValueError:
            break
        updated = True
        if refit.angle_deg(plane) < 1e-6 and abs(refit.d - plane.d) < 1e-9:
            plane = refit
            break
        plane = refit
    return plane, updated


def update_min_points(params: Params) -> float:
    """Floor voxels needed to refit: 300 * 0.06 / voxel_size / sampling_factor^2 (OpenPTrack)."""
    reference_voxel = 0.06
    return (
        float(params.ground_update_min_points)
        * reference_voxel
        / float(params.voxel_size)
        / float(params.sampling_factor) ** 2
    )


def automatic_ground(points: np.ndarray, params: Params) -> Plane | None:
    """The lowest large near-horizontal plane below the camera, refined; None when there is none.

    OpenPTrack's automatic mode: planes whose normal is within
    ``ground_max_tilt`` of the camera's down direction (and that lie below
    the camera) are candidates; the one whose inliers' centroid is lowest in
    the camera's view (largest y) wins.
    """
    cos_tilt = math.cos(math.radians(float(params.ground_max_tilt)))
    below = [
        c
        for c in segment_planes(points, params)
        if -(c.plane.normal @ CAMERA_DOWN) >= cos_tilt  # normal up = camera's -y
    ]
    if not below:
        return None
    lowest = max(below, key=lambda c: float(c.centroid @ CAMERA_DOWN))
    plane, _ = refine_ground(lowest.plane, points, params)
    return plane


def semi_automatic_ground(points: np.ndarray, pick: Sequence[float], params: Params) -> Plane:
    """Semi-automatic ground: the segmented plane the operator picked a point of
    (camera frame, metres): the one with an inlier nearest to it, refined."""
    candidates = segment_planes(points, params)
    if not candidates:
        raise GroundError(
            "no plane was found in the cloud; point the sensor at the floor or give three floor points."
        )
    pick = np.asarray(pick, dtype=np.float64)
    nearest = min(candidates, key=lambda c: float(np.min(np.linalg.norm(c.points - pick, axis=1))))
    plane, _ = refine_ground(nearest.plane, points, params)
    return check_ground(plane, "the chosen plane")


def combine_with_calibration(
    cloud_plane: Plane | None, calibration_plane: Plane, points: np.ndarray, params: Params
) -> tuple[Plane, str]:
    """OpenPTrack's rule (``computeMulticamera``): keep the calibration's floor, refined
    against the cloud, when the cloud's floor is missing or its camera height differs
    by more than ``calibration_ground_tolerance``; else keep the cloud's.

    Returns the plane and where it came from (``"cloud"`` or ``"calibration"``).
    """
    if cloud_plane is not None and abs(cloud_plane.d - calibration_plane.d) <= float(
        params.calibration_ground_tolerance
    ):
        return cloud_plane, "cloud"
    refined, _ = refine_ground(calibration_plane, points, params)
    return refined, "calibration"


class GroundFile(msgspec.Struct, forbid_unknown_fields=True):
    """A saved ground plane (camera frame of ``sensor_id``)."""

    sensor_id: str
    plane: tuple[float, float, float, float]
    source: str = ""
    saved: str = ""


def default_ground_directory() -> Path:
    base = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    return Path(base) / "optrack" / "ground"


class GroundStore:
    """Ground planes saved per sensor, one JSON file each (``ground_<sensor>.json``)."""

    def __init__(self, directory: str | os.PathLike[str] | None = None) -> None:
        self.directory = Path(directory) if directory is not None else default_ground_directory()

    def path(self, sensor_id: str) -> Path:
        safe = re.sub(r"[^A-Za-z0-9_.-]", "_", sensor_id)
        return self.directory / f"ground_{safe}.json"

    def save(self, sensor_id: str, plane: Plane, source: str = "") -> Path:
        record = GroundFile(
            sensor_id,
            tuple(plane.to_list()),  # type: ignore[arg-type]
            source,
            datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        )
        path = self.path(sensor_id)
        atomic_write_bytes(path, msgspec.json.format(msgspec.json.encode(record)) + b"\n")
        return path

    def load(self, sensor_id: str) -> Plane | None:
        """The saved plane of a sensor, or None when none was saved."""
        path = self.path(sensor_id)
        if not path.is_file():
            return None
        try:
            record = msgspec.json.decode(path.read_bytes(), type=GroundFile)
        except (msgspec.DecodeError, msgspec.ValidationError) as error:
            raise GroundError(
                f"saved ground plane {path} is damaged ({error}); delete it to estimate the floor again."
            ) from None
        return check_ground(record.plane, f"the saved ground plane in {path}")


class GroundEstimator:
    """One sensor's floor across frames.

    The first usable frame initialises it (in order of preference: a plane
    given by the operator, the saved plane when ``read_ground_from_file``,
    the calibration combined with the cloud's plane, the cloud's plane);
    afterwards each frame's floor points refit it unless ``lock_ground``.
    Planes are saved to and read from ``store`` (default: the user's
    ``~/.config/optrack/ground``).
    """

    def __init__(
        self,
        params: Params,
        plane: Plane | None = None,
        calibration: Plane | None = None,
        store: GroundStore | None = None,
        sensor_id: str = "sensor",
    ) -> None:
        self.params = params
        self.calibration = calibration
        self.store = store
        self.sensor_id = sensor_id
        self.plane: Plane | None = check_ground(plane) if plane is not None else None
        self.source = "manual" if plane is not None else ""

    @property
    def ready(self) -> bool:
        return self.plane is not None

    def initialise(self, points: np.ndarray, valid_fraction: float = 1.0) -> bool:
        """Estimate the floor from a voxelised cloud; True when there is one now."""
        if self.plane is not None:
            return True
        p = self.params
        if p.read_ground_from_file:
            saved = (self.store or GroundStore()).load(self.sensor_id)
            if saved is not None:
                self.plane, self.source = saved, "file"
                return True
        if valid_fraction < float(p.valid_points_threshold):
            return False  # OpenPTrack waits for a frame with enough depth
        cloud_plane = automatic_ground(points, p)
        if self.calibration is not None and p.ground_from_calibration:
            self.plane, self.source = combine_with_calibration(
                cloud_plane, self.calibration, points, p
            )
        elif cloud_plane is not None:
            self.plane, self.source = cloud_plane, "cloud"
        return self.plane is not None

    def update(self, points: np.ndarray) -> np.ndarray:
        """Heights of the points above the current floor; then the floor is refitted to
        this frame's floor points, those within ``ground_inlier_distance``, unless
        locked or too few (OpenPTrack's order: remove the floor, then refit it; it
        refits to its floor voxels, here to up to ``FIT_POINTS`` floor points evenly
        spread)."""
        assert self.plane is not None, "initialise the ground first"
        a, b, c, d = (points.dtype.type(v) for v in self.plane.coefficients)
        # Element-wise, not ``points @ normal``: a BLAS call on a tall Nx3 array is
        # many times slower, and slower still on a busy machine.
        heights = points[:, 0] * a + points[:, 1] * b + points[:, 2] * c + d
        if self.params.lock_ground:
            return heights
        inliers = np.flatnonzero(np.abs(heights) < float(self.params.ground_inlier_distance))
        step = max(1, len(inliers) // FIT_POINTS)
        self.refit(points[inliers[::step]], len(inliers))
        return heights

    def refit(self, floor: np.ndarray, count: int) -> None:
        """Refit the floor to ``floor`` points (up to ``FIT_POINTS`` of this frame's
        ``count`` floor points) unless locked or ``count`` is too few (OpenPTrack's
        ``ground_update_min_points``)."""
        if self.params.lock_ground or count < max(update_min_points(self.params), 3):
            return
        try:
            refit = Plane.fit(floor).oriented_towards((0.0, 0.0, 0.0))
        except ValueError:
            return
        if abs(refit.d) >= MIN_CAMERA_HEIGHT:
            self.plane = refit

    def save(self) -> Path | None:
        """Save the current plane for this sensor (in the default store when none was
        given); None when there is no plane yet."""
        if self.plane is None:
            return None
        return (self.store or GroundStore()).save(self.sensor_id, self.plane, self.source)
