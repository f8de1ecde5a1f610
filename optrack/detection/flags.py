"""The detector's flags on a person: partly out of the image, occluded.

``out_of_view``: more than ``out_of_view_fraction`` of the head-to-floor box
(its width half its height) is outside the image. ``occluded``: more than
``occlusion_fraction`` of the pixels in front of the body show something
above the floor and nearer to the sensor by ``occlusion_margin``.
"""

from __future__ import annotations

import math

import numpy as np

from optrack.params import Params
from optrack.types import Intrinsics

__all__ = ["is_occluded", "outside_fraction"]


def outside_fraction(pixels: np.ndarray, person_px: float, shape: tuple[int, int]) -> float:
    """Fraction of the head-to-floor box (width half its height) outside the image."""
    rows, cols = shape
    top, bottom = pixels[0][1], pixels[1][1]
    half = person_px / 4.0
    left, right = pixels[2][0] - half, pixels[2][0] + half
    area = max((bottom - top) * (right - left), 1e-9)
    inside_w = max(0.0, min(right, cols) - max(left, 0.0))
    inside_h = max(0.0, min(bottom, rows) - max(top, 0.0))
    return float(1.0 - inside_w * inside_h / area)


def is_occluded(
    params: Params,
    crop_g: tuple[np.ndarray, ...],
    valid: np.ndarray,
    head: tuple[float, float],
    pixels: np.ndarray,
    origin: tuple[int, int],
    stride: int,
    intrinsics: Intrinsics,
    depth: float,
) -> bool:
    """Whether more than ``occlusion_fraction`` of the pixels in front of the body
    (head to floor, ``person_radius`` either side of its axis) show something above
    the floor and nearer to the sensor than the person by ``occlusion_margin``."""
    p = params
    gx, gy, gz = crop_g
    if gz.size == 0:
        return False
    person_range = math.hypot(*head)  # the camera stands over the ground frame's origin
    u0, v0 = origin
    half = float(p.person_radius) * intrinsics.fx / max(depth, 1e-6)
    c0 = max(0, int((pixels[2][0] - half - u0) / stride))
    c1 = min(gz.shape[1], int(math.ceil((pixels[2][0] + half - u0) / stride)))
    r0 = max(0, int((pixels[0][1] - v0) / stride))
    r1 = min(gz.shape[0], int(math.ceil((pixels[1][1] - v0) / stride)))
    if c1 <= c0 or r1 <= r0:
        return False
    body = (slice(r0, r1), slice(c0, c1))
    with np.errstate(invalid="ignore"):
        nearer = (
            valid[body]
            & (gz[body] > float(p.ground_inlier_distance))
            & (np.hypot(gx[body], gy[body]) < person_range - float(p.occlusion_margin))
        )
    return float(np.count_nonzero(nearer)) / nearer.size > float(p.occlusion_fraction)
