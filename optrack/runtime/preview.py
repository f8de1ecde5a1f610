"""Down-sampled previews of a detector's frames for the GUI (``optrack/<site>/preview/<sensor>``).

A preview is the depth image scaled to ``node.preview_width`` pixels wide
(16-bit PNG, millimetres), the registered colour image at the same size
with the detection boxes drawn (JPEG), the detections with their boxes in
preview pixels, and a decimated point cloud (world frame when the sensor is
calibrated). A few per second are enough for a GUI, and cost a node a few
milliseconds each.
"""

from __future__ import annotations

import cv2
import msgspec
import numpy as np

from optrack.geometry import backproject_points, transform_points
from optrack.net.messages import PreviewMessage
from optrack.types import DetectionBatch, Matrix4, RGBDFrame, as_matrix4

__all__ = ["decode_preview", "make_preview"]

BOX_RGB = (255, 64, 32)
JPEG_QUALITY = 80


def _scale_box(box: tuple[int, int, int, int], factor: float) -> tuple[int, int, int, int]:
    u, v, w, h = box
    return (round(u * factor), round(v * factor), round(w * factor), round(h * factor))


def make_preview(
    frame: RGBDFrame,
    batch: DetectionBatch,
    world_T_camera: np.ndarray | None,
    width: int,
    points: int,
    stamp: float,
) -> PreviewMessage:
    """The preview of one frame and what was detected in it."""
    h, w = frame.depth.shape
    factor = min(1.0, width / w)
    size = (max(1, round(w * factor)), max(1, round(h * factor)))
    intrinsics = frame.intrinsics.scaled(factor)
    if intrinsics.width != size[0] or intrinsics.height != size[1]:
        intrinsics = msgspec.structs.replace(intrinsics, width=size[0], height=size[1])
    depth_mm = cv2.resize(frame.depth_mm(), size, interpolation=cv2.INTER_NEAREST)
    ok, depth_png = cv2.imencode(".png", depth_mm, [cv2.IMWRITE_PNG_COMPRESSION, 1])
    detections = [
        msgspec.structs.replace(d, box=_scale_box(d.box, factor)) for d in batch.detections
    ]
    color_jpeg = b""
    if frame.color is not None and frame.color.shape[:2] == frame.depth.shape:
        color = cv2.resize(frame.color, size, interpolation=cv2.INTER_AREA)
        bgr = cv2.cvtColor(color, cv2.COLOR_RGB2BGR)
        for d in detections:
            u, v, bw, bh = d.box
            cv2.rectangle(bgr, (u, v), (u + bw, v + bh), BOX_RGB[::-1], 1)
        ok_color, encoded = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
        if ok_color:
            color_jpeg = encoded.tobytes()
    cloud = b""
    cloud_frame = "camera"
    pose: Matrix4 | None = None
    if points > 0:
        xyz, _ = backproject_points(depth_mm.astype(np.float32) / 1000.0, intrinsics)
        if len(xyz) > points:
            xyz = xyz[np.linspace(0, len(xyz) - 1, points).astype(np.int64)]
        if world_T_camera is not None:
            xyz = transform_points(world_T_camera, xyz)
            cloud_frame = "world"
            pose = as_matrix4(world_T_camera)
        cloud = np.ascontiguousarray(xyz, dtype=np.float16).tobytes()
    return PreviewMessage(
        sensor=frame.sensor_id,
        stamp=stamp,
        intrinsics=intrinsics,
        depth_png=depth_png.tobytes() if ok else b"",
        color_jpeg=color_jpeg,
        detections=msgspec.structs.replace(batch, detections=detections),
        cloud=cloud,
        cloud_frame=cloud_frame,
        world_T_camera=pose,
    )


def decode_preview(message: PreviewMessage) -> tuple[RGBDFrame, np.ndarray]:
    """The preview as a frame (depth in millimetres, colour when sent) and its cloud (Nx3)."""
    depth = cv2.imdecode(np.frombuffer(message.depth_png, np.uint8), cv2.IMREAD_UNCHANGED)
    if depth is None:
        raise ValueError(f"the preview of sensor '{message.sensor}' has no readable depth image")
    color = None
    if message.color_jpeg:
        bgr = cv2.imdecode(np.frombuffer(message.color_jpeg, np.uint8), cv2.IMREAD_COLOR)
        if bgr is not None and bgr.shape[:2] == depth.shape:
            color = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
    frame = RGBDFrame(
        depth=depth,
        intrinsics=message.intrinsics,
        sensor_id=message.sensor,
        timestamp=message.stamp,
        depth_scale=0.001,
        color=color,
    )
    cloud = np.frombuffer(message.cloud, dtype=np.float16).reshape(-1, 3).astype(np.float32)
    return frame, cloud
