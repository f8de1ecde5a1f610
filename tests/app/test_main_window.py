"""The main window on a real X server (Xvfb) with OpenGL: run by `make test-gl`."""

import os
import subprocess
import sys

import numpy as np
import pytest
from PySide6.QtGui import QImage

pytestmark = pytest.mark.opengl


def image_array(image: QImage) -> np.ndarray:
    """RGB copy of a QImage as an HxWx3 array."""
    image = image.convertToFormat(QImage.Format.Format_RGB888)
    height, width, stride = image.height(), image.width(), image.bytesPerLine()
    raw = np.array(image.constBits(), dtype=np.uint8, copy=True)[: height * stride]
    return raw.reshape(height, stride)[:, : width * 3].reshape(height, width, 3)


def test_main_window_shows_the_floor_grid_in_opengl(qtbot):
    from app.main_window import MainWindow

    window = MainWindow()
    qtbot.addWidget(window)
    window.show()
    qtbot.waitExposed(window)
    assert window.world.width() > 300 and window.world.height() > 200
    frame = image_array(window.world.grabFramebuffer())
    background = np.array([25, 28, 34])
    grid = np.abs(frame.astype(int) - background).sum(axis=2) > 60
    assert grid.mean() > 0.005  # grid lines were drawn
    assert grid.mean() < 0.5  # and the background is still the background
    assert window.site_label.text() == "No site connected"


def test_optrack_gui_takes_a_screenshot_and_quits(tmp_path):
    shot = tmp_path / "window.png"
    optrack = os.path.join(os.path.dirname(sys.executable), "optrack")
    result = subprocess.run(
        [optrack, "gui", "--screenshot", str(shot), "--quit-after", "2"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    image = QImage(str(shot))
    assert (image.width(), image.height()) == (1280, 800)
    pixels = image_array(image)
    assert len(np.unique(pixels.reshape(-1, 3), axis=0)) > 10
