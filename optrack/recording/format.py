"""The recording format: a session directory that streams frame by frame.

::

    SESSION/
      manifest.yaml                 format, version, sensors (model, intrinsics, true pose)
      sensors/<id>/index.jsonl      append-only, one line per frame, in time order
      sensors/<id>/depth/<seq>.png  16-bit depth, millimetres
      sensors/<id>/color/<seq>.jpg  colour (JPEG or PNG, see the `recording` parameters)
      sensors/<id>/infrared/<seq>.png, confidence/<seq>.png   when the sensor has them
      ground_truth.jsonl            optional, append-only: people (and boards) per instant

A frame's image files are written first and its index line last, so a
writer killed at any moment leaves every indexed frame readable; a last
line cut short by the kill is ignored. Each sensor's index is in time
order, so readers merge sensors in constant memory.

The reader makes the writer's checks: an index or a ground truth that goes
back in time, or an index entry naming a file outside its sensor's folder
(an absolute path, ``..``), is refused as damaged. On closing, the writer
announces its counts in the manifest (``extra.frames`` per sensor,
``extra.ground_truth_instants``); a recording that holds fewer is read with
one warning saying how much is missing.
"""

from __future__ import annotations

import re

import msgspec

from optrack.errors import UserError
from optrack.params import Param, Schema, register
from optrack.types import Intrinsics, Matrix4

FORMAT_NAME = "optrack-recording"
FORMAT_VERSION = 1
MANIFEST = "manifest.yaml"
GROUND_TRUTH = "ground_truth.jsonl"
SENSORS_DIR = "sensors"
INDEX = "index.jsonl"
STREAMS = ("depth", "color", "infrared", "confidence")
SENSOR_ID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$")

RECORDING_PARAMS = register(
    Schema(
        "recording",
        [
            Param(
                "color_format",
                "jpg",
                choices=("jpg", "png"),
                help="Colour image encoding: JPEG (small) or PNG (lossless).",
            ),
            Param(
                "jpeg_quality", 95, min=50, max=100, step=1, help="JPEG quality for colour images."
            ),
            Param(
                "png_compression",
                1,
                min=0,
                max=9,
                step=1,
                help="PNG compression level (0 fastest, 9 smallest).",
            ),
        ],
        help="How recordings store images.",
    )
)


class RecordingError(UserError):
    """A recording that cannot be read or written."""


class SensorInfo(msgspec.Struct, forbid_unknown_fields=True):
    """What a recording knows of one sensor."""

    id: str
    intrinsics: Intrinsics
    model: str = ""
    uri: str = ""
    depth_scale: float = 0.001
    color_intrinsics: Intrinsics | None = None
    world_T_camera: Matrix4 | None = None
    fps: float | None = None
    streams: list[str] = msgspec.field(default_factory=lambda: ["depth"])


class Manifest(msgspec.Struct, forbid_unknown_fields=True):
    format: str
    version: int
    sensors: list[SensorInfo]
    created: str = ""
    source: str = ""
    ground_truth: bool = False
    extra: dict[str, object] = {}


class IndexEntry(msgspec.Struct, forbid_unknown_fields=True, omit_defaults=True):
    """One line of a sensor's index: the frame's time and its files (relative)."""

    seq: int
    t: float
    depth: str
    color: str | None = None
    infrared: str | None = None
    confidence: str | None = None


# Joint names recordings written before the skeleton's vocabulary used, and theirs now.
LEGACY_JOINT_NAMES = {
    f"{joint}_{side[0]}": f"{side}_{joint}"
    for joint in ("shoulder", "elbow", "wrist", "hip", "knee", "ankle")
    for side in ("left", "right")
}


class PersonTruth(msgspec.Struct, forbid_unknown_fields=True, omit_defaults=True):
    """One person's true state: floor position (world, metres), height, and optionally
    the fraction of the body visible from each sensor, 3D joint positions (world,
    metres) and joint angles (rotation vectors, radians: each joint's rotation
    relative to its parent, the pelvis's relative to the world; zero is standing
    straight, arms hanging). Joints are named as optrack.skeleton.joints names them;
    older recordings' names (``wrist_l``) are read as today's (``left_wrist``)."""

    id: int
    x: float
    y: float
    height: float
    visible: dict[str, float] = {}
    joints: dict[str, tuple[float, float, float]] = {}
    angles: dict[str, tuple[float, float, float]] = {}

    def __post_init__(self) -> None:
        if any(name in LEGACY_JOINT_NAMES for name in self.joints):
            self.joints = {LEGACY_JOINT_NAMES.get(k, k): v for k, v in self.joints.items()}


class BoardTruth(msgspec.Struct, forbid_unknown_fields=True, omit_defaults=True):
    """A checkerboard's true pose (board frame at its first inner corner)."""

    world_T_board: Matrix4
    cols: int
    rows: int
    square: float
    on_floor: bool = False


class GroundTruth(msgspec.Struct, forbid_unknown_fields=True, omit_defaults=True):
    """Everything true at one instant."""

    t: float
    people: list[PersonTruth] = []
    boards: list[BoardTruth] = []
