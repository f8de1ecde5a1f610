"""The Sensors dock: status rows from the nodes, and previews with the detector's boxes."""

import numpy as np
import pytest
from PySide6.QtGui import QImage

from app.widgets.preview import BOX_COLOR, depth_image
from app.widgets.sensors_panel import ERROR_COLOR, SensorsPanel
from optrack.types import Detection, DetectionBatch, Intrinsics, RGBDFrame

KINECT = Intrinsics(525.0, 525.0, 319.5, 239.5, width=640, height=480)


def image_array(image: QImage) -> np.ndarray:
    image = image.convertToFormat(QImage.Format.Format_RGB888)
    height, width, stride = image.height(), image.width(), image.bytesPerLine()
    raw = np.array(image.constBits(), dtype=np.uint8, copy=True)[: height * stride]
    return raw.reshape(height, stride)[:, : width * 3].reshape(height, width, 3)


def box_pixels(widget) -> int:
    pixels = image_array(widget.grab().toImage()).astype(int)
    color = np.array([BOX_COLOR.red(), BOX_COLOR.green(), BOX_COLOR.blue()])
    return int((np.abs(pixels - color).sum(axis=2) < 40).sum())


def test_status_rows_show_each_sensors_health(qtbot):
    panel = SensorsPanel()
    qtbot.addWidget(panel)
    panel.set_status(
        "detector/kitchen",
        {
            "sensor": "kitchen",
            "fps": 29.97,
            "latency_ms": 41.6,
            "clock_offset_ms": -2.25,
            "dropped": 3,
            "last_error": "",
        },
    )
    panel.set_status("tracker", {"fps": 30.0})  # not a sensor: not a row
    assert panel.table.rowCount() == 1
    shown = {k.replace("\n", " "): v for k, v in panel.status_text("kitchen").items()}
    assert shown == {
        "sensor": "kitchen",
        "fps": "30.0",
        "latency (ms)": "42",
        "offset (ms)": "-2.2",
        "dropped": "3",
        "last error": "",
    }
    panel.set_status(
        "detector/kitchen",
        {"sensor": "kitchen", "fps": 0.0, "last_error": "sensor 'kitchen' was unplugged"},
    )
    assert panel.status_text("kitchen")["last error"] == "sensor 'kitchen' was unplugged"
    assert panel.table.rowCount() == 1


def test_a_sensor_that_stops_reporting_is_greyed_out(qtbot):
    panel = SensorsPanel(stale_after=0.05)
    qtbot.addWidget(panel)
    panel.set_status("detector/door", {"sensor": "door", "fps": 30.0})
    qtbot.wait(100)
    panel.mark_stale()
    assert "No status from sensor 'door'" in panel.table.item(0, 0).toolTip()


def test_depth_picture_is_black_where_there_is_no_depth():
    depth = np.full((4, 4), 2.0, dtype=np.float32)
    depth[0, 0] = np.nan
    picture = depth_image(RGBDFrame(depth, Intrinsics(2, 2, 1.5, 1.5)))
    assert picture.shape == (4, 4, 3) and picture.dtype == np.uint8
    assert (picture[0, 0] == 0).all() and picture[1, 1].sum() > 0


@pytest.fixture(scope="module")
def five_people(shared_data):
    """PCL's real Kinect frame of five people and the project's detector's result on it."""
    from optrack.detection.params import detection_params
    from optrack.detection.pipeline import PeopleDetector
    from optrack.io.pcd import read_pcd

    cloud = read_pcd(shared_data / "pcl" / "five_people.pcd")
    points = cloud.points.reshape(480, 640, 3)
    colors = cloud.colors.reshape(480, 640, 3)
    detector = PeopleDetector(
        detection_params("pcl"), ground=(-0.0103586, 0.997011, 0.0765573, -1.26614)
    )
    batch = detector.process_cloud(points, KINECT, color=colors)
    depth = np.where(np.isfinite(points[..., 2]), points[..., 2], np.nan).astype(np.float32)
    frame = RGBDFrame(depth, KINECT, sensor_id="corridor", color=colors)
    return frame, batch


def test_preview_draws_the_detectors_boxes_on_depth_and_colour(qtbot, five_people):
    frame, batch = five_people
    assert len(batch.detections) == 5
    panel = SensorsPanel()
    qtbot.addWidget(panel)
    panel.resize(400, 700)
    panel.show()
    panel.set_preview("corridor", frame, batch)
    assert panel.sensor_choice.currentText() == "corridor"
    preview = panel.preview
    assert [label.split(":")[0] for _, label in preview.boxes] == ["0", "1", "2", "3", "4"]
    assert box_pixels(preview) > 200
    panel.stream_choice.setCurrentIndex(panel.stream_choice.findData("color"))
    assert preview.image is not None and len(preview.boxes) == 5
    assert box_pixels(preview) > 200
    panel.set_preview("corridor", frame, DetectionBatch("corridor", 0.0))  # nobody found
    assert preview.boxes == [] and box_pixels(preview) == 0


def test_preview_says_when_a_sensor_has_no_such_stream(qtbot):
    panel = SensorsPanel()
    qtbot.addWidget(panel)
    depth = np.full((48, 64), 1.5, dtype=np.float32)
    frame = RGBDFrame(depth, Intrinsics(52.5, 52.5, 31.5, 23.5, 64, 48), sensor_id="door")
    batch = DetectionBatch(
        "door", 0.0, detections=[Detection(1, 2, 1, 1.7, 0.9, box=(5, 5, 10, 20))]
    )
    panel.set_preview("door", frame, batch)
    assert panel.preview.image is not None
    panel.stream_choice.setCurrentIndex(panel.stream_choice.findData("infrared"))
    assert panel.preview.image is None
    assert panel.preview.message == "Sensor 'door' sends no infrared image."


def test_a_detectors_status_is_listed_under_its_sensor(qtbot):
    panel = SensorsPanel()
    qtbot.addWidget(panel)
    panel.set_status(
        "kinect2_0",
        {
            "role": "detector",
            "state": "starting",
            "sensor": "file:///venue?loop=true#kinect2_0",
            "fps": 0.0,
            "clock_offset_ms": -0.0,
        },
    )
    shown = panel.status_text("kinect2_0")
    assert shown["offset\n(ms)"] == "+0.0"
    # starting is no error: said in grey, short enough for a narrow dock, and explained
    assert shown["last error"] == "starting"
    item = panel.table.item(0, 5)
    assert item.foreground().color() != ERROR_COLOR
    assert "is starting; no problem so far" in item.toolTip()
    assert "file:///venue" in panel.table.item(0, 0).toolTip()


def test_dropped_frames_say_why_and_whether_they_matter(qtbot):
    panel = SensorsPanel()
    qtbot.addWidget(panel)
    panel.set_status("kinect2_1", {"role": "detector", "state": "running", "dropped": 14000})
    assert panel.status_text("kinect2_1")["dropped"] == "14000"
    tip = panel.table.item(0, 4).toolTip()
    assert tip.startswith("14000 frames skipped so far.")
    assert "takes the newest frame" in tip and "matters when fps gets low" in tip
    assert "newest frame" in panel.table.horizontalHeaderItem(4).toolTip()
    panel.set_status("kinect2_1", {"role": "detector", "last_error": "unplugged"})
    assert panel.table.item(0, 5).foreground().color() == ERROR_COLOR
