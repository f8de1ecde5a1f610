"""Wire messages: versioned, validated msgspec structs around optrack's types.

Every payload on the bus is one :class:`Message` encoded with MessagePack.
Its first fields are ``kind`` (which message it is) and ``v`` (the wire
version, :data:`WIRE_VERSION`). :func:`decode` checks, in this order, the
size, that the bytes are a MessagePack map with ``v`` and ``kind``, the
version, the kind expected on that key, the full structure (unknown fields
refused, as in :mod:`optrack.types`), and finally that every number is
finite. Each failure is a :class:`MessageError` whose ``reason`` is one of
:data:`REJECT_REASONS`; the bus counts it and drops the message.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any, TypeVar

import msgspec
import numpy as np

from optrack.errors import UserError
from optrack.types import (
    DetectionBatch,
    Intrinsics,
    Matrix4,
    NetworkCalibration,
    SkeletonBatch,
    TrackBatch,
)

__all__ = [
    "REJECT_REASONS",
    "WIRE_VERSION",
    "BoardViewMessage",
    "CalibrationMessage",
    "ClockReply",
    "ClockRequest",
    "CommandReply",
    "CommandRequest",
    "DestinationStatus",
    "DetectionsMessage",
    "MAX_PERSON_POINTS",
    "Message",
    "MessageError",
    "PersonCloud",
    "PersonCloudsMessage",
    "ParamValue",
    "ParamsMessage",
    "PreviewMessage",
    "SkeletonsMessage",
    "StatusMessage",
    "TracksMessage",
    "decode",
    "encode",
]

WIRE_VERSION = 1

# Why a received message was refused (the keys of the bus's reject counters).
REJECT_REASONS = ("too_large", "malformed", "version", "kind", "invalid")

ParamValue = bool | int | float | str


class MessageError(UserError):
    """A received payload that is not a valid message of the expected kind."""

    def __init__(self, reason: str, sentence: str) -> None:
        super().__init__(sentence)
        self.reason = reason


class Message(msgspec.Struct, tag_field="kind", kw_only=True, forbid_unknown_fields=True):
    """Fields every message has: the wire version and the sending node."""

    v: int = WIRE_VERSION
    sender: str = ""

    def check(self) -> None:
        """Raise ValueError when a value is out of its domain (e.g. a NaN position)."""


def _finite(what: str, values: Iterable[float | None]) -> None:
    for value in values:
        if value is not None and not math.isfinite(value):
            raise ValueError(f"{what} holds a non-finite number ({value})")


class DetectionsMessage(Message, tag="detections"):
    """One sensor's detections; ``batch.stamp`` is already in tracker time.

    ``clock_offset_s`` is the offset (tracker clock minus node clock) the node
    applied, and ``clock_uncertainty_s`` its bound (half the best round trip).
    """

    batch: DetectionBatch
    clock_offset_s: float = 0.0
    clock_uncertainty_s: float | None = None

    def check(self) -> None:
        batch = self.batch
        _finite("detections stamp", (batch.stamp, batch.processing_ms, self.clock_offset_s))
        for d in batch.detections:
            _finite("a detection", (d.x, d.y, d.z, d.height, d.confidence))
            if d.camera_xyz is not None:
                _finite("a detection's camera_xyz", d.camera_xyz)
        if batch.ground is not None:
            _finite("the ground plane", batch.ground)


class TracksMessage(Message, tag="tracks"):
    """The tracker's output at one moment."""

    batch: TrackBatch

    def check(self) -> None:
        _finite("tracks stamp", (self.batch.stamp,))
        for t in self.batch.tracks:
            _finite("a track", (t.x, t.y, t.height, t.vx, t.vy, t.age, t.confidence))


class SkeletonsMessage(Message, tag="skeletons"):
    """The skeleton node's output at one moment."""

    batch: SkeletonBatch

    def check(self) -> None:
        _finite("skeletons stamp", (self.batch.stamp,))
        for skeleton in self.batch.skeletons:
            _finite("a skeleton", (skeleton.height, skeleton.rate_hz))
            for joint in skeleton.joints.values():
                _finite("a skeleton joint", joint)


#: The most points one person's cloud may carry on the bus (per sensor and frame).
MAX_PERSON_POINTS = 4096


class PersonCloud(msgspec.Struct, forbid_unknown_fields=True):
    """One person's decimated points as one sensor saw them.

    ``x, y, height``: the detection (world frame, metres); ``points``: float16
    x, y, z triples relative to ``(x, y, 0)`` (so float16 keeps millimetres),
    at most :data:`MAX_PERSON_POINTS`.
    """

    x: float
    y: float
    height: float
    points: bytes = b""

    def world_points(self) -> np.ndarray:
        """The points in the world frame, (N, 3) float64."""
        offsets = np.frombuffer(self.points, dtype=np.float16).reshape(-1, 3)
        return offsets.astype(np.float64) + np.array([self.x, self.y, 0.0])


class PersonCloudsMessage(Message, tag="person_clouds"):
    """Every person one sensor's detector found in one frame, with their points
    (published only while the skeleton stage is on); ``stamp`` in tracker time."""

    sensor: str
    stamp: float
    clouds: list[PersonCloud] = []

    def check(self) -> None:
        _finite("person clouds stamp", (self.stamp,))
        for cloud in self.clouds:
            _finite("a person cloud", (cloud.x, cloud.y, cloud.height))
            if len(cloud.points) % 6 or len(cloud.points) // 6 > MAX_PERSON_POINTS:
                raise ValueError(
                    f"a person cloud holds {len(cloud.points)} bytes; it must be float16 "
                    f"x, y, z triples, at most {MAX_PERSON_POINTS} points"
                )
            if not np.all(np.isfinite(np.frombuffer(cloud.points, dtype=np.float16))):
                raise ValueError("a person cloud holds a non-finite point")


class CalibrationMessage(Message, tag="calibration"):
    """A network calibration for every node to store and use from its next frame."""

    calibration: NetworkCalibration


class ParamsMessage(Message, tag="params"):
    """Parameter updates for one node: ``{stage: {name: value}}``, applied all-or-nothing
    between two frames. ``request`` is echoed in the node's status."""

    updates: dict[str, dict[str, ParamValue]]
    request: str = ""


class DestinationStatus(msgspec.Struct, forbid_unknown_fields=True):
    """One output destination as the outputs node reports it."""

    kind: str  # "udp", "osc" or "websocket"
    address: str
    enabled: bool = True
    sent: int = 0
    errors: int = 0
    clients: int = 0
    last_error: str = ""


class StatusMessage(Message, tag="status"):
    """A node's health, published about once a second.

    ``role`` is ``detector``, ``tracker``, ``outputs`` or ``site``; ``state``
    is ``starting``, ``running``, ``ended``, ``stopping`` or ``error``.
    ``latency_ms`` is the node's own processing latency (capture to publish
    for a detector; detection stamp to track output for the tracker).
    ``counters`` holds the bus's receive and reject counts; ``params`` the
    node's current parameter values per stage.
    """

    node: str
    role: str
    state: str
    stamp: float
    uptime_s: float = 0.0
    sensor: str = ""
    fps: float = 0.0
    latency_ms: float = 0.0
    dropped: int = 0
    clock_offset_ms: float | None = None
    clock_uncertainty_ms: float | None = None
    last_error: str = ""
    counters: dict[str, int] = {}
    values: dict[str, ParamValue] = {}
    params: dict[str, dict[str, ParamValue]] = {}
    destinations: list[DestinationStatus] = []
    request: str = ""

    def check(self) -> None:
        _finite("status", (self.stamp, self.fps, self.latency_ms))


class PreviewMessage(Message, tag="preview"):
    """A down-sampled frame of one sensor for the GUI (a few per second).

    ``depth_png`` is 16-bit PNG in millimetres at the size ``intrinsics``
    describe; ``color_jpeg`` is JPEG of the same size with the detection boxes
    drawn (empty when the sensor has no colour); ``detections`` has its boxes
    in preview pixels; ``cloud`` is a decimated point cloud, world frame when
    ``world_T_camera`` is known (else camera frame), float16 x,y,z triples.
    """

    sensor: str
    stamp: float
    intrinsics: Intrinsics
    depth_png: bytes
    color_jpeg: bytes = b""
    detections: DetectionBatch | None = None
    cloud: bytes = b""
    cloud_frame: str = "camera"
    world_T_camera: Matrix4 | None = None


class BoardViewMessage(Message, tag="board_view"):
    """One frame a detector node searched for the checkerboard during a calibration
    capture (a few per second).

    ``stamp`` is the frame's capture time in tracker time; ``corners`` the
    board's inner corners in full-resolution pixels of ``image`` (``color`` or
    ``infrared``, whose ``intrinsics`` they are), in board order, or None when
    the board was not found; ``on_floor`` whether the board lies on the floor
    (the node's depth test; None when the depth is not registered to the image);
    ``preview_jpeg`` a small JPEG of the image with the corners drawn.
    """

    sensor: str
    stamp: float
    phase: str
    seq: int
    image: str
    intrinsics: Intrinsics
    corners: list[tuple[float, float]] | None = None
    on_floor: bool | None = None
    preview_jpeg: bytes = b""
    model: str = ""
    search_ms: float = 0.0

    def check(self) -> None:
        _finite("board view", (self.stamp, self.search_ms))
        if self.corners is not None:
            _finite("board corners", (v for corner in self.corners for v in corner))


class CommandRequest(Message, tag="command"):
    """Ask one node to act now (``action``, with ``args``); answered by a
    :class:`CommandReply`. Commands are for acts (start or stop a recording or a
    calibration capture, a simulated operator's move); settings go in
    :class:`ParamsMessage`."""

    action: str
    args: dict[str, Any] = {}


class CommandReply(Message, tag="command_reply"):
    """A node's answer to a command: ``ok``, a sentence for the operator (why it was
    refused, or what was done) and the action's ``result``."""

    node: str
    action: str
    ok: bool
    sentence: str = ""
    result: dict[str, Any] = {}


class ClockRequest(Message, tag="clock_request"):
    """NTP-style request: ``t0`` is the node's clock when it sent it."""

    t0: float


class ClockReply(Message, tag="clock_reply"):
    """NTP-style reply: ``t1`` when the tracker received the request, ``t2`` when it replied
    (tracker clock), ``t0`` echoed."""

    t0: float
    t1: float
    t2: float

    def check(self) -> None:
        _finite("clock reply", (self.t0, self.t1, self.t2))


class _Header(msgspec.Struct):
    """The two fields read before anything else (other fields ignored)."""

    v: int
    kind: str


_encoder = msgspec.msgpack.Encoder()
_header_decoder = msgspec.msgpack.Decoder(_Header)
_decoders: dict[type, msgspec.msgpack.Decoder[Any]] = {}

M = TypeVar("M", bound=Message)


def kind_of(cls: type[Message]) -> str:
    return str(cls.__struct_config__.tag)


def encode(message: Message) -> bytes:
    """The message as MessagePack bytes."""
    return _encoder.encode(message)


def decode(data: bytes | bytearray | memoryview, cls: type[M], max_bytes: int | None = None) -> M:
    """The message of kind ``cls`` in ``data``, or a :class:`MessageError` saying why not."""
    expected = kind_of(cls)
    if max_bytes is not None and len(data) > max_bytes:
        raise MessageError(
            "too_large",
            f"a {expected} message of {len(data)} bytes is larger than the {max_bytes}-byte limit "
            "(bus.max_message_bytes).",
        )
    try:
        header = _header_decoder.decode(data)
    except (msgspec.DecodeError, msgspec.ValidationError):
        raise MessageError(
            "malformed", f"a payload is not an optrack message (expected a {expected} message)."
        ) from None
    if header.v != WIRE_VERSION:
        raise MessageError(
            "version",
            f"a {header.kind!r} message has wire version {header.v}; this optrack speaks version "
            f"{WIRE_VERSION}, so run the same optrack version on every node.",
        )
    if header.kind != expected:
        raise MessageError(
            "kind", f"a {header.kind!r} message arrived where a {expected} message belongs."
        )
    decoder = _decoders.get(cls)
    if decoder is None:
        decoder = _decoders[cls] = msgspec.msgpack.Decoder(cls)
    try:
        message = decoder.decode(data)
        message.check()
    except (msgspec.DecodeError, msgspec.ValidationError, ValueError) as error:
        raise MessageError("invalid", f"a {expected} message is invalid: {error}.") from None
    return message
