"""Wire messages: what a node accepts, and the reason it gives for what it refuses."""

from __future__ import annotations

import math

import msgspec
import numpy as np
import pytest

from optrack.net.messages import (
    WIRE_VERSION,
    CalibrationMessage,
    ClockReply,
    DetectionsMessage,
    MessageError,
    ParamsMessage,
    PreviewMessage,
    StatusMessage,
    TracksMessage,
    decode,
    encode,
)
from optrack.types import (
    Detection,
    DetectionBatch,
    Intrinsics,
    NetworkCalibration,
    SensorCalibration,
    Track,
    TrackBatch,
)

IDENTITY = tuple(tuple(float(v) for v in row) for row in np.eye(4))


def detections(x: float = 1.0) -> DetectionsMessage:
    return DetectionsMessage(
        batch=DetectionBatch(
            "cam0",
            12.5,
            seq=3,
            detections=[Detection(x, 2.0, 0.9, 1.75, 0.4, box=(1, 2, 3, 4), histogram=[0.5, 0.5])],
            ground=(0.0, 0.0, 1.0, 0.0),
        ),
        clock_offset_s=-0.25,
        clock_uncertainty_s=0.0001,
    )


def raw(message: msgspec.Struct, **changes: object) -> bytes:
    data = msgspec.to_builtins(message)
    data.update(changes)
    return msgspec.msgpack.encode(data)


@pytest.mark.parametrize(
    "message",
    [
        detections(),
        TracksMessage(batch=TrackBatch(1.0, tracks=[Track(7, 1.0, 2.0, 1.8, age=3.0)])),
        CalibrationMessage(
            calibration=NetworkCalibration(
                sensors={"cam0": SensorCalibration(world_T_camera=IDENTITY)}
            )
        ),
        ParamsMessage(updates={"detection": {"voxel_size": 0.08, "hog_image": "color"}}),
        StatusMessage(node="cam0", role="detector", state="running", stamp=1.0, fps=29.9),
        PreviewMessage(
            sensor="cam0", stamp=1.0, intrinsics=Intrinsics(100, 100, 80, 60), depth_png=b"\x89PNG"
        ),
        ClockReply(t0=1.0, t1=2.0, t2=2.1),
    ],
    ids=lambda m: type(m).__name__,
)
def test_every_message_kind_round_trips(message):
    back = decode(encode(message), type(message))
    assert back == message
    assert back.v == WIRE_VERSION


def test_message_starts_with_kind_and_version():
    data = msgspec.msgpack.decode(encode(detections()))
    assert data["kind"] == "detections"
    assert data["v"] == WIRE_VERSION


def test_other_wire_version_is_refused_as_version():
    with pytest.raises(MessageError) as error:
        decode(raw(detections(), v=WIRE_VERSION + 1), DetectionsMessage)
    assert error.value.reason == "version"
    assert "same optrack version" in str(error.value)


def test_message_of_another_kind_is_refused_as_kind():
    tracks = TracksMessage(batch=TrackBatch(1.0))
    with pytest.raises(MessageError) as error:
        decode(encode(tracks), DetectionsMessage)
    assert error.value.reason == "kind"


@pytest.mark.parametrize(
    "payload",
    [b"", b"\x00\x01garbage", b'{"kind": "detections", "v": 1}', msgspec.msgpack.encode([1, 2])],
)
def test_bytes_that_are_not_a_message_are_refused_as_malformed(payload):
    with pytest.raises(MessageError) as error:
        decode(payload, DetectionsMessage)
    assert error.value.reason == "malformed"


def test_unknown_field_is_refused_as_invalid():
    with pytest.raises(MessageError) as error:
        decode(raw(detections(), surprise=1), DetectionsMessage)
    assert error.value.reason == "invalid"


def test_wrong_field_type_is_refused_as_invalid():
    data = msgspec.to_builtins(detections())
    data["batch"]["detections"][0]["x"] = "left"
    with pytest.raises(MessageError) as error:
        decode(msgspec.msgpack.encode(data), DetectionsMessage)
    assert error.value.reason == "invalid"


def test_nan_position_is_refused_as_invalid():
    with pytest.raises(MessageError) as error:
        decode(encode(detections(x=math.nan)), DetectionsMessage)
    assert error.value.reason == "invalid"
    assert "non-finite" in str(error.value)


def test_calibration_with_a_non_rigid_pose_is_refused_as_invalid():
    data = msgspec.to_builtins(
        CalibrationMessage(
            calibration=NetworkCalibration(
                sensors={"cam0": SensorCalibration(world_T_camera=IDENTITY)}
            )
        )
    )
    pose = [list(row) for row in data["calibration"]["sensors"]["cam0"]["world_T_camera"]]
    pose[0][0] = 2.0  # a scaled, not rotated, axis
    data["calibration"]["sensors"]["cam0"]["world_T_camera"] = pose
    with pytest.raises(MessageError) as error:
        decode(msgspec.msgpack.encode(data), CalibrationMessage)
    assert error.value.reason == "invalid"


def test_payload_over_the_limit_is_refused_before_decoding():
    payload = encode(detections())
    with pytest.raises(MessageError) as error:
        decode(payload, DetectionsMessage, max_bytes=len(payload) - 1)
    assert error.value.reason == "too_large"
    assert decode(payload, DetectionsMessage, max_bytes=len(payload)) == detections()
