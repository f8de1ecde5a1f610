"""A sensor's live preview: depth, colour or infrared, with the detector's boxes."""

from __future__ import annotations

import cv2
import numpy as np
from PySide6.QtCore import QRectF, Qt
from PySide6.QtGui import QColor, QFont, QImage, QPainter, QPen
from PySide6.QtWidgets import QSizePolicy, QWidget

from app.source import NO_SITE
from optrack.types import DetectionBatch, RGBDFrame

STREAMS = ("depth", "color", "infrared")
BOX_COLOR = QColor(255, 220, 40)


def depth_image(frame: RGBDFrame, near: float = 0.5, far: float = 8.0) -> np.ndarray:
    """Depth as an RGB uint8 picture: near is red, far is blue, no depth is black."""
    metres = frame.depth_m()
    scaled = np.clip((metres - near) / (far - near), 0.0, 1.0)
    grey = np.nan_to_num(255.0 * (1.0 - scaled), nan=0.0).astype(np.uint8)
    rgb = cv2.cvtColor(cv2.applyColorMap(grey, cv2.COLORMAP_TURBO), cv2.COLOR_BGR2RGB)
    rgb[~np.isfinite(metres)] = 0
    return rgb


def infrared_image(frame: RGBDFrame) -> np.ndarray:
    """Infrared stretched to its 1st-99th percentiles, as RGB uint8."""
    values = frame.infrared.astype(np.float32)
    low, high = np.percentile(values, [1, 99])
    grey = np.clip((values - low) / max(high - low, 1e-6) * 255.0, 0, 255).astype(np.uint8)
    return np.repeat(grey[:, :, None], 3, axis=2)


def stream_image(frame: RGBDFrame, stream: str) -> np.ndarray | None:
    """The picture of one stream, RGB uint8 HxWx3, or None when the frame lacks it."""
    if stream == "depth":
        return depth_image(frame)
    if stream == "color":
        return frame.color
    if stream == "infrared":
        return None if frame.infrared is None else infrared_image(frame)
    raise ValueError(f"unknown stream '{stream}'; pick one of {', '.join(STREAMS)}.")


def to_qimage(rgb: np.ndarray) -> QImage:
    rgb = np.ascontiguousarray(rgb)
    height, width, _ = rgb.shape
    return QImage(rgb.data, width, height, 3 * width, QImage.Format.Format_RGB888).copy()


class PreviewView(QWidget):
    """Paints one stream of the latest frame, scaled to fit, and the detection boxes.

    Boxes are in depth-image pixels, so they are drawn on the depth and infrared
    pictures and on a colour picture registered to the depth image.
    """

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setMinimumSize(160, 120)
        self.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Expanding)
        self.stream = "depth"
        self.image: QImage | None = None
        self.boxes: list[tuple[tuple[int, int, int, int], str]] = []
        self.message = NO_SITE

    def show_frame(self, frame: RGBDFrame | None, batch: DetectionBatch | None) -> None:
        self.image, self.boxes = None, []
        if frame is None:
            self.message = "No preview yet."
        else:
            rgb = stream_image(frame, self.stream)
            if rgb is None:
                self.message = f"Sensor '{frame.sensor_id}' sends no {self.stream} image."
            else:
                self.image = to_qimage(rgb)
                registered = rgb.shape[:2] == frame.depth.shape
                if batch is not None and registered:
                    self.boxes = [
                        (d.box, f"{i}: {d.confidence:+.2f}")
                        for i, d in enumerate(batch.detections)
                        if d.box[2] > 0 and d.box[3] > 0
                    ]
        self.update()

    def paintEvent(self, event) -> None:  # noqa: N802 - Qt
        painter = QPainter(self)
        painter.fillRect(self.rect(), QColor(25, 28, 34))
        if self.image is None:
            painter.setPen(QColor(220, 220, 220))
            flags = Qt.AlignmentFlag.AlignCenter | Qt.TextFlag.TextWordWrap
            painter.drawText(self.rect().adjusted(8, 8, -8, -8), flags, self.message)
            return
        width, height = self.image.width(), self.image.height()
        scale = min(self.width() / width, self.height() / height)
        left = (self.width() - width * scale) / 2
        top = (self.height() - height * scale) / 2
        target = QRectF(left, top, width * scale, height * scale)
        painter.drawImage(target, self.image)
        pen = QPen(BOX_COLOR)
        pen.setWidth(2)
        font = QFont()
        font.setPointSize(9)
        painter.setFont(font)
        metrics = painter.fontMetrics()
        for (u, v, w, h), label in self.boxes:
            rect = QRectF(left + u * scale, top + v * scale, w * scale, h * scale)
            painter.setPen(pen)
            painter.drawRect(rect)
            if metrics.horizontalAdvance(label) + 6 > rect.width():
                label = label.split(":")[0]  # a narrow box: its index only
            tag = QRectF(
                rect.left(), rect.top(), metrics.horizontalAdvance(label) + 6, metrics.height()
            )
            painter.fillRect(tag, BOX_COLOR)
            painter.setPen(QColor(0, 0, 0))
            painter.drawText(tag, Qt.AlignmentFlag.AlignCenter, label)
