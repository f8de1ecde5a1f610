"""Shared vocabulary: the values every stage of optrack passes along.

Conventions (see docs/architecture.md):

* Units are metres, seconds and radians.
* World frame: origin on the floor, z up. Camera frame: OpenCV (x right,
  y down, z forward).
* Poses are ``world_T_camera`` 4x4 arrays unless a name says otherwise.
* Colour images are RGB, uint8, HxWx3 (OpenCV's BGR is converted at the
  OpenCV boundary).

Values that cross a process boundary (detections, tracks, calibrations) are
``msgspec.Struct`` types, so that the bus and the files validate them; the
frame, which never leaves its sensor's process, is a dataclass of arrays.
"""

from __future__ import annotations

import dataclasses
import enum
import math

import msgspec
import numpy as np

from optrack.errors import UserError

__all__ = [
    "Detection",
    "DetectionBatch",
    "Intrinsics",
    "NetworkCalibration",
    "SITE_REACH_M",
    "RGBDFrame",
    "SensorCalibration",
    "Skeleton",
    "SkeletonBatch",
    "Track",
    "TrackBatch",
    "TrackStatus",
    "pose_problem",
]


class Intrinsics(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """Pinhole camera intrinsics in pixels, with OpenCV distortion.

    ``dist`` holds OpenCV's coefficients in its order (k1, k2, p1, p2[, k3
    [, k4, k5, k6]]); empty means no distortion. ``width`` and ``height`` are
    the image size the intrinsics belong to (0 when unknown). Pixel centres
    are at integer coordinates: pixel column ``u`` looks along
    ``x = (u - cx) / fx`` (PCL's and OpenCV's convention).
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int = 0
    height: int = 0
    dist: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        # UserError (a ValueError): values come from command lines and files a user wrote
        for name in ("fx", "fy", "cx", "cy"):
            value = getattr(self, name)
            if not math.isfinite(value):
                raise UserError(f"intrinsics {name} must be a finite number; got {value}.")
        if self.fx <= 0 or self.fy <= 0:
            raise UserError(
                f"intrinsics focal lengths must be positive; got fx={self.fx}, fy={self.fy}."
            )
        if self.width < 0 or self.height < 0:
            raise UserError(f"intrinsics image size must be >= 0; got {self.width}x{self.height}.")
        if not all(math.isfinite(c) for c in self.dist):
            raise UserError(f"intrinsics dist must be finite numbers; got {list(self.dist)}.")
        if len(self.dist) not in (0, 4, 5, 8):
            raise UserError(
                f"intrinsics dist must hold 0, 4, 5 or 8 OpenCV coefficients; got {len(self.dist)}."
            )

    @classmethod
    def parse(cls, text: str, width: int = 0, height: int = 0) -> Intrinsics:
        """Parse ``"fx,fy,cx,cy"`` as given on the command line: four finite numbers, the
        focal lengths positive."""
        parts = [p for p in text.replace(" ", "").split(",") if p]
        try:
            values = [float(p) for p in parts]
        except ValueError:
            values = []
        if len(values) != 4:
            raise UserError(
                f"intrinsics must be four numbers 'fx,fy,cx,cy' (pixels); got '{text}'."
            )
        if not all(math.isfinite(v) for v in values) or min(values[:2]) <= 0:
            raise UserError(
                f"intrinsics '{text}' must be four finite numbers fx,fy,cx,cy in pixels with "
                "focal lengths fx and fy above 0 (e.g. 525,525,319.5,239.5)."
            )
        return cls(*values, width=width, height=height)

    @property
    def K(self) -> np.ndarray:  # noqa: N802 - the textbook name
        """The 3x3 camera matrix."""
        return np.array(
            [[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]], dtype=np.float64
        )

    @property
    def dist_coeffs(self) -> np.ndarray:
        """Distortion coefficients as OpenCV expects them (zeros when none)."""
        return np.array(self.dist if self.dist else (0.0,) * 5, dtype=np.float64)

    @property
    def has_distortion(self) -> bool:
        return any(c != 0.0 for c in self.dist)

    def scaled(self, factor: float) -> Intrinsics:
        """Intrinsics of the same camera with the image resized by ``factor``.

        Uses the pixel-centre convention: a pixel centre at u maps to
        ``(u + 0.5) * factor - 0.5``.
        """
        return Intrinsics(
            fx=self.fx * factor,
            fy=self.fy * factor,
            cx=(self.cx + 0.5) * factor - 0.5,
            cy=(self.cy + 0.5) * factor - 0.5,
            width=round(self.width * factor),
            height=round(self.height * factor),
            dist=self.dist,
        )


def _check_image(
    name: str, image: np.ndarray | None, shape: tuple[int, int], channels: int
) -> None:
    if image is None:
        return
    if not isinstance(image, np.ndarray):
        raise TypeError(f"frame {name} must be a numpy array; got {type(image).__name__}.")
    expected_ndim = 2 if channels == 1 else 3
    if image.ndim != expected_ndim or (channels > 1 and image.shape[2] != channels):
        raise ValueError(
            f"frame {name} must be {'HxW' if channels == 1 else f'HxWx{channels}'}; "
            f"got shape {image.shape}."
        )


@dataclasses.dataclass(eq=False)
class RGBDFrame:
    """One capture of one sensor.

    ``depth`` is either float (metres; 0 or NaN where invalid) or uint16
    with ``depth_scale`` metres per unit (0.001 for millimetres; 0 invalid).
    ``color`` is RGB uint8 HxWx3; when it is not registered to the depth
    image, ``color_intrinsics`` describes it. ``infrared`` (uint8 or
    uint16) and ``confidence`` (any numeric, larger is better) have the
    depth image's size. ``timestamp`` is in seconds (the sensor's clock
    unless the runtime restamped it).
    """

    depth: np.ndarray
    intrinsics: Intrinsics
    sensor_id: str = "sensor"
    timestamp: float = 0.0
    depth_scale: float = 1.0
    color: np.ndarray | None = None
    infrared: np.ndarray | None = None
    confidence: np.ndarray | None = None
    color_intrinsics: Intrinsics | None = None
    seq: int = 0

    def __post_init__(self) -> None:
        if not isinstance(self.depth, np.ndarray) or self.depth.ndim != 2:
            shape = getattr(self.depth, "shape", None)
            raise ValueError(f"frame depth must be an HxW array; got shape {shape}.")
        if self.depth.dtype == np.uint16:
            if not 0 < self.depth_scale < math.inf:
                raise UserError(
                    f"depth scale {self.depth_scale} must be a finite number of metres per depth "
                    "unit above 0 (0.001 for millimetres)."
                )
        elif self.depth.dtype.kind != "f":
            raise ValueError(
                f"frame depth must be float metres or uint16 with a scale; got {self.depth.dtype}."
            )
        h, w = self.depth.shape
        k = self.intrinsics
        if k.width and k.height and (k.width, k.height) != (w, h):
            raise ValueError(
                f"frame of sensor '{self.sensor_id}': depth is {w}x{h} but its intrinsics are "
                f"for {k.width}x{k.height}."
            )
        _check_image("color", self.color, (h, w), 3)
        if (
            self.color is not None
            and self.color_intrinsics is None
            and self.color.shape[:2] != (h, w)
        ):
            raise ValueError(
                f"frame colour is {self.color.shape[1]}x{self.color.shape[0]} but depth is "
                f"{w}x{h}; give color_intrinsics for an unregistered colour image."
            )
        for name in ("infrared", "confidence"):
            image = getattr(self, name)
            _check_image(name, image, (h, w), 1)
            if image is not None and image.shape != (h, w):
                raise ValueError(
                    f"frame {name} is {image.shape[1]}x{image.shape[0]} but depth is {w}x{h}."
                )

    @property
    def shape(self) -> tuple[int, int]:
        """(height, width) of the depth image."""
        return self.depth.shape  # type: ignore[return-value]

    def depth_m(self) -> np.ndarray:
        """Depth in metres as float32, NaN where invalid."""
        if self.depth.dtype == np.uint16:
            out = (self.depth * self.depth_scale).astype(np.float32)
            out[self.depth == 0] = np.nan
            return out
        out = self.depth.astype(np.float32, copy=True)
        out[~(out > 0)] = np.nan  # zeros, negatives and NaN
        return out

    def depth_mm(self) -> np.ndarray:
        """Depth in millimetres as uint16, 0 where invalid (the recording's encoding)."""
        if self.depth.dtype == np.uint16 and self.depth_scale == 0.001:
            return self.depth
        metres = self.depth_m()
        mm = np.rint(np.nan_to_num(metres, nan=0.0) * 1000.0)
        if mm.max(initial=0) > np.iinfo(np.uint16).max:
            raise ValueError(
                f"frame of sensor '{self.sensor_id}' has depth beyond 65.535 m; "
                "it cannot be stored as 16-bit millimetres."
            )
        return mm.astype(np.uint16)


class Detection(msgspec.Struct, forbid_unknown_fields=True):
    """One person found by one sensor's detector.

    ``x, y, z`` is the centroid in the batch's frame (world frame unless the
    batch says ``camera``); ``z`` is the centroid height above the floor in
    the world frame. ``height`` is the top of the head above the ground
    plane. ``box`` is (u, v, width, height) in the depth image, pixels.
    ``camera_xyz`` is the centroid in the camera frame. ``histogram`` is a
    normalised colour histogram of the person's pixels (empty when none).
    """

    x: float
    y: float
    z: float
    height: float
    confidence: float
    box: tuple[int, int, int, int] = (0, 0, 0, 0)
    camera_xyz: tuple[float, float, float] | None = None
    occluded: bool = False
    out_of_view: bool = False
    histogram: list[float] = []

    @property
    def position(self) -> np.ndarray:
        return np.array([self.x, self.y, self.z], dtype=np.float64)


class DetectionBatch(msgspec.Struct, forbid_unknown_fields=True):
    """Everything one sensor found in one frame."""

    sensor_id: str
    stamp: float
    seq: int = 0
    frame_id: str = "world"
    detections: list[Detection] = []
    ground: tuple[float, float, float, float] | None = None
    processing_ms: float = 0.0
    # The voxel size the detector down-sampled with (m), the base of the position noise
    # the tracker gives these detections; 0 when the source does not say.
    voxel_size: float = 0.0


class TrackStatus(enum.StrEnum):
    """Life-cycle state of a track (Munaro 2012, section 5.4)."""

    NEW = "new"
    NORMAL = "normal"
    MISSING = "missing"


class Track(msgspec.Struct, forbid_unknown_fields=True):
    """A tracked person in the world frame (ground plane)."""

    id: int
    x: float
    y: float
    height: float
    vx: float = 0.0
    vy: float = 0.0
    age: float = 0.0
    confidence: float = 0.0
    status: TrackStatus = TrackStatus.NEW
    sensors: list[str] = []


class TrackBatch(msgspec.Struct, forbid_unknown_fields=True):
    """All tracks at one moment (the tracker's output)."""

    stamp: float
    seq: int = 0
    frame_id: str = "world"
    tracks: list[Track] = []


Matrix4 = tuple[
    tuple[float, float, float, float],
    tuple[float, float, float, float],
    tuple[float, float, float, float],
    tuple[float, float, float, float],
]


def as_matrix4(pose: np.ndarray) -> Matrix4:
    """A 4x4 pose as the nested tuples of floats that messages and files carry."""
    rows = np.asarray(pose, dtype=np.float64).reshape(4, 4)
    return tuple(tuple(float(v) for v in row) for row in rows)  # type: ignore[return-value]


# No camera of a site is further than this from its world's origin (m).
SITE_REACH_M = 1000.0


def pose_problem(matrix: np.ndarray, tolerance: float = 1e-4) -> str | None:
    """What keeps a 4x4 matrix from being a camera's pose in a site, to follow its name
    in a sentence (None when nothing does): not finite, not a rotation and a translation,
    or a translation beyond :data:`SITE_REACH_M`."""
    if matrix.shape != (4, 4) or not np.all(np.isfinite(matrix)):
        return "must be a finite 4x4 matrix"
    rotation = matrix[:3, :3]
    if (
        not np.allclose(matrix[3], (0.0, 0.0, 0.0, 1.0), atol=tolerance)
        or not np.allclose(rotation @ rotation.T, np.eye(3), atol=tolerance)
        or np.linalg.det(rotation) < 0
    ):
        return "is not a rigid transform (a rotation and a translation)"
    distance = math.hypot(*matrix[:3, 3].tolist())  # no overflow near the largest floats
    if distance > SITE_REACH_M:
        return f"moves {distance:.4g} m, beyond the {SITE_REACH_M:g} m a site spans"
    return None


def _check_rigid(name: str, matrix: np.ndarray, tolerance: float = 1e-4) -> None:
    problem = pose_problem(matrix, tolerance)
    if problem is not None:
        raise ValueError(f"{name} {problem}.")


class SensorCalibration(msgspec.Struct, forbid_unknown_fields=True):
    """Where one sensor is in the world, and how it sees."""

    world_T_camera: Matrix4
    intrinsics: Intrinsics | None = None
    model: str = ""
    reprojection_rms_px: float | None = None

    def __post_init__(self) -> None:
        _check_rigid("world_T_camera", np.asarray(self.world_T_camera, dtype=np.float64))

    @property
    def pose(self) -> np.ndarray:
        return np.asarray(self.world_T_camera, dtype=np.float64)


class NetworkCalibration(msgspec.Struct, forbid_unknown_fields=True):
    """The whole network's calibration: every sensor's ``world_T_camera``.

    The world frame has its origin on the floor and z up, so the ground
    plane is z = 0 by definition; ``ground`` keeps the plane (a, b, c, d)
    actually measured, for checks.
    """

    sensors: dict[str, SensorCalibration] = {}
    ground: tuple[float, float, float, float] = (0.0, 0.0, 1.0, 0.0)
    version: int = 1
    created: str = ""
    notes: str = ""

    def pose(self, sensor_id: str) -> np.ndarray:
        """``world_T_camera`` of a sensor, 4x4."""
        try:
            return self.sensors[sensor_id].pose
        except KeyError:
            known = ", ".join(sorted(self.sensors)) or "none"
            raise UserError(
                f"the calibration has no sensor '{sensor_id}' (it has: {known}); "
                "calibrate that sensor or pick one of those."
            ) from None

    def with_pose(
        self, sensor_id: str, world_T_camera: np.ndarray, **fields: object
    ) -> NetworkCalibration:
        """A copy with one sensor's pose set (other fields of that sensor kept)."""
        matrix = tuple(tuple(float(v) for v in row) for row in np.asarray(world_T_camera))
        sensors = dict(self.sensors)
        old = sensors.get(sensor_id)
        base = msgspec.structs.asdict(old) if old is not None else {}
        base.update(fields)
        base["world_T_camera"] = matrix
        sensors[sensor_id] = SensorCalibration(**base)  # type: ignore[arg-type]
        return msgspec.structs.replace(self, sensors=sensors)


class Skeleton(msgspec.Struct, forbid_unknown_fields=True):
    """One tracked person's skeleton (world frame, metres).

    ``id`` is the person's track id; ``state`` is ``initialising``, ``tracking``
    or ``lost``; ``rate_hz`` how often this skeleton is updated; ``joints`` maps a
    joint name (optrack/skeleton/joints.py) to ``(x, y, z, confidence)``, confidence
    in 0..1; a joint with no position (a lost skeleton) is left out.
    """

    id: int
    height: float
    state: str
    rate_hz: float = 0.0
    joints: dict[str, tuple[float, float, float, float]] = {}


class SkeletonBatch(msgspec.Struct, forbid_unknown_fields=True):
    """Every current skeleton at one moment (the skeleton node's output)."""

    stamp: float
    seq: int = 0
    frame_id: str = "world"
    skeletons: list[Skeleton] = []
