import msgspec
import numpy as np
import pytest

from optrack.errors import UserError
from optrack.types import (
    Detection,
    DetectionBatch,
    Intrinsics,
    NetworkCalibration,
    RGBDFrame,
    Track,
    TrackBatch,
    TrackStatus,
)

K = Intrinsics(525, 525, 319.5, 239.5, 640, 480)


def test_intrinsics_parse_command_line_form():
    parsed = Intrinsics.parse("525,525,319.5,239.5", 640, 480)
    assert parsed == K
    np.testing.assert_allclose(parsed.K, [[525, 0, 319.5], [0, 525, 239.5], [0, 0, 1]])


@pytest.mark.parametrize("text", ["525,525,319.5", "a,b,c,d", ""])
def test_intrinsics_parse_rejects_malformed_text(text):
    with pytest.raises(UserError, match="fx,fy,cx,cy"):
        Intrinsics.parse(text)


def test_intrinsics_reject_non_positive_focal_length_and_odd_distortion():
    with pytest.raises(ValueError, match="positive"):
        Intrinsics(0, 525, 320, 240)
    with pytest.raises(ValueError, match="coefficients"):
        Intrinsics(525, 525, 320, 240, dist=(0.1, 0.2, 0.3))


@pytest.mark.parametrize(
    "text", ["0,0,32,24", "nan,nan,32,24", "inf,525,32,24", "-300,-300,32,24", "525,525,nan,0"]
)
def test_intrinsics_parse_names_the_value_and_the_range(text):
    with pytest.raises(UserError) as error:
        Intrinsics.parse(text, 64, 48)
    assert str(error.value) == (
        f"intrinsics '{text}' must be four finite numbers fx,fy,cx,cy in pixels with focal "
        "lengths fx and fy above 0 (e.g. 525,525,319.5,239.5)."
    )


def test_intrinsics_and_depth_scales_a_user_gave_are_user_errors():
    """A user's value (command line, file) fails with one sentence, not a traceback."""
    with pytest.raises(UserError, match="intrinsics fx must be a finite number; got nan"):
        Intrinsics(float("nan"), 525, 320, 240)
    with pytest.raises(UserError, match="dist must be finite"):
        Intrinsics(525, 525, 320, 240, dist=(0.1, float("inf"), 0.0, 0.0))
    depth = np.zeros((2, 2), np.uint16)
    for scale in (-1.0, float("nan"), float("inf")):
        with pytest.raises(UserError, match=f"depth scale {scale} must be a finite number"):
            RGBDFrame(depth, Intrinsics(1, 1, 0, 0), depth_scale=scale)


def test_intrinsics_scaled_keeps_pixel_centres():
    half = K.scaled(0.5)
    assert (half.width, half.height) == (320, 240)
    assert half.fx == pytest.approx(262.5)
    assert half.cx == pytest.approx((319.5 + 0.5) * 0.5 - 0.5)


def test_frame_depth_in_millimetres_converts_to_metres_with_nan_holes():
    depth = np.array([[0, 1500], [2000, 65535]], np.uint16)
    frame = RGBDFrame(depth, Intrinsics(1, 1, 0, 0, 2, 2), depth_scale=0.001)
    metres = frame.depth_m()
    assert metres.dtype == np.float32
    assert np.isnan(metres[0, 0])
    np.testing.assert_allclose(
        metres[0, 1:].tolist() + metres[1].tolist(), [1.5, 2.0, 65.535], rtol=1e-6
    )
    np.testing.assert_array_equal(frame.depth_mm(), depth)


def test_frame_float_depth_round_trips_to_millimetres():
    depth = np.array([[np.nan, 0.0012], [4.2, -1.0]], np.float32)
    frame = RGBDFrame(depth, Intrinsics(1, 1, 0, 0))
    np.testing.assert_array_equal(frame.depth_mm(), [[0, 1], [4200, 0]])


def test_frame_rejects_mismatched_images_with_a_sentence():
    depth = np.zeros((480, 640), np.uint16)
    with pytest.raises(ValueError, match="intrinsics are for 320x240"):
        RGBDFrame(depth, Intrinsics(1, 1, 0, 0, 320, 240), depth_scale=0.001)
    with pytest.raises(ValueError, match="color_intrinsics"):
        RGBDFrame(depth, K, depth_scale=0.001, color=np.zeros((240, 320, 3), np.uint8))
    with pytest.raises(ValueError, match="infrared is 320x240"):
        RGBDFrame(depth, K, depth_scale=0.001, infrared=np.zeros((240, 320), np.uint16))
    with pytest.raises(ValueError, match="uint16 with a scale"):
        RGBDFrame(depth.astype(np.int32), K)


def test_detection_and_track_batches_round_trip_through_json():
    batch = DetectionBatch(
        sensor_id="kinect-1",
        stamp=12.5,
        seq=3,
        detections=[
            Detection(
                1.0,
                2.0,
                0.9,
                1.75,
                -0.4,
                box=(10, 20, 30, 80),
                camera_xyz=(0.1, 0.2, 3.0),
                histogram=[0.5, 0.5],
            )
        ],
        ground=(0.0, 0.0, 1.0, 0.0),
    )
    assert msgspec.json.decode(msgspec.json.encode(batch), type=DetectionBatch) == batch
    tracks = TrackBatch(
        stamp=1.0, tracks=[Track(7, 1.0, 2.0, 1.8, status=TrackStatus.NORMAL, sensors=["a"])]
    )
    decoded = msgspec.json.decode(msgspec.json.encode(tracks), type=TrackBatch)
    assert decoded == tracks
    assert decoded.tracks[0].status is TrackStatus.NORMAL


def test_malformed_detection_message_is_rejected_by_validation():
    with pytest.raises(msgspec.ValidationError):
        msgspec.json.decode(b'{"sensor_id": "a", "stamp": "soon"}', type=DetectionBatch)
    with pytest.raises(msgspec.ValidationError):
        msgspec.json.decode(b'{"sensor_id": "a", "stamp": 1, "surprise": 2}', type=DetectionBatch)


def test_network_calibration_holds_rigid_poses_only():
    pose = np.eye(4)
    pose[:3, 3] = [1, 2, 3]
    calibration = NetworkCalibration().with_pose("cam0", pose, model="kinect2")
    np.testing.assert_allclose(calibration.pose("cam0"), pose)
    assert calibration.sensors["cam0"].model == "kinect2"
    moved = calibration.with_pose("cam0", np.eye(4))
    assert moved.sensors["cam0"].model == "kinect2"
    sheared = np.eye(4)
    sheared[0, 1] = 0.5
    with pytest.raises(ValueError, match="not a rigid transform"):
        calibration.with_pose("cam1", sheared)
    with pytest.raises(UserError, match="no sensor 'cam9'.*cam0"):
        calibration.pose("cam9")
    far = np.eye(4)
    far[:3, 3] = [1e308, 0.0, 0.0]
    with pytest.raises(ValueError, match="moves 1e[+]308 m, beyond the 1000 m a site spans"):
        calibration.with_pose("cam1", far)
    text = msgspec.json.encode(calibration)
    assert msgspec.json.decode(text, type=NetworkCalibration) == calibration
