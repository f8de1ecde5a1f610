"""Depth and colour images from files (16-bit TIFF/PNG depth, 8-bit colour)."""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np

from optrack.errors import UserError

__all__ = ["ImageError", "read_color_image", "read_depth_image"]


class ImageError(UserError):
    """An image file that cannot be used."""


def _read(path: Path, what: str) -> np.ndarray:
    if not path.exists():
        raise ImageError(f"{what} {path} does not exist; check the path.")
    if path.is_dir():
        raise ImageError(f"{what} {path} is a directory, not an image file.")
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise ImageError(f"{what} {path} is not an image OpenCV can read (use PNG or TIFF).")
    return image


def read_depth_image(path: str | os.PathLike[str]) -> np.ndarray:
    """A depth image as stored: HxW uint16 (sensor units, usually mm) or float32 metres."""
    path = Path(path)
    image = _read(path, "depth image")
    if image.ndim != 2:
        raise ImageError(
            f"depth image {path} has {image.shape[2]} channels; a depth image has one "
            "(16-bit millimetres or 32-bit float metres)."
        )
    if image.dtype == np.uint16 or image.dtype == np.float32:
        return image
    raise ImageError(
        f"depth image {path} is {image.dtype}; depth must be 16-bit (with --depth-scale, "
        "0.001 for millimetres) or 32-bit float metres."
    )


def read_color_image(path: str | os.PathLike[str]) -> np.ndarray:
    """A colour image as RGB uint8 HxWx3."""
    path = Path(path)
    image = _read(path, "colour image")
    if image.dtype == np.uint16:
        image = (image >> 8).astype(np.uint8)
    if image.ndim == 2:
        return cv2.cvtColor(image, cv2.COLOR_GRAY2RGB)
    if image.shape[2] == 4:
        return cv2.cvtColor(image, cv2.COLOR_BGRA2RGB)
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
