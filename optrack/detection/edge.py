"""People cut by the image's left or right border.

A person walking out of a sensor's view is a cluster of their visible part.
Two things go wrong with it if it is treated as a whole person: the
classifier's full-body window, centred on the person, is partly black (the
score falls below the threshold), and the head centroid, the person's floor
position, is that of the visible part of the head, pulled into the image.

- :func:`lateral_cut` tells which border cuts a person's head-to-floor box.
- :func:`corrected_head` puts a cut head's centre ``edge_head_radius`` inside
  its visible inner edge (the edge of the head away from the border), where
  the visible points' centroid would be half way between the border and that
  edge; a head the border does not cut keeps its centroid.
- :func:`border_window` is the classifier's window centred on the border at
  the person's distance and scale (not squeezed): sampled with the image
  mirrored at its border (:func:`~optrack.detection.classifier.person_window`
  with ``mirror``), it shows the visible part and its mirror image, a whole
  upright figure, which the full-body classifier can judge.
"""

from __future__ import annotations

import numpy as np

from optrack.detection.classifier import level_window
from optrack.types import Intrinsics

__all__ = ["border_window", "corrected_head", "lateral_cut"]

#: Half the head-to-floor box's width, as a fraction of the person's height (the box's
#: width is half its height, as :func:`~optrack.detection.flags.outside_fraction`'s).
BOX_HALF_WIDTH = 0.25


def _border_slope(side: int, intrinsics: Intrinsics) -> float:
    """x/z of the image's left (-1) or right (+1) border, camera frame."""
    u = -0.5 if side < 0 else intrinsics.width - 0.5
    return (u - intrinsics.cx) / intrinsics.fx


def lateral_cut(center_c: np.ndarray, height: float, intrinsics: Intrinsics) -> int:
    """-1 when the image's left border cuts the person's head-to-floor box (its width
    half its height, centred on ``center_c``, camera frame), +1 the right one, else 0."""
    x, z = float(center_c[0]), float(center_c[2])
    if z <= 0:
        return 0
    half = BOX_HALF_WIDTH * height
    if (x - half) / z < _border_slope(-1, intrinsics):
        return -1
    if (x + half) / z > _border_slope(1, intrinsics):
        return 1
    return 0


def _inward_normal(side: int, intrinsics: Intrinsics) -> np.ndarray:
    """Unit normal of the border's plane (through the optical centre), pointing into the
    image, camera frame."""
    slope = _border_slope(side, intrinsics)
    normal = np.array([1.0, 0.0, -slope]) if side < 0 else np.array([-1.0, 0.0, slope])
    return normal / np.linalg.norm(normal)


def corrected_head(
    points: np.ndarray,
    height: float,
    head: np.ndarray,
    side: int,
    c_T_g: np.ndarray,
    intrinsics: Intrinsics,
    head_fraction: float,
    head_radius: float,
    cut_distance: float,
) -> np.ndarray:
    """The floor position (ground frame x, y) of a person whose ``side`` border cuts the
    box: ``head`` (the head centroid) when no head point is within ``cut_distance`` of the
    border's plane, else the head centroid moved across the border's plane to
    ``head_radius`` inside the head's visible inner edge. ``points`` are the candidate's
    voxels (ground frame, z up)."""
    top = points[points[:, 2] >= height * (1.0 - head_fraction)]
    if side == 0 or len(top) == 0:
        return head
    normal_c = _inward_normal(side, intrinsics)
    camera = top @ c_T_g[:3, :3].T + c_T_g[:3, 3]
    inside = camera @ normal_c
    if float(inside.min()) > cut_distance:
        return head
    # The normal in the ground frame, along the floor: the direction to move the head.
    normal_g = c_T_g[:3, :3].T @ normal_c
    along = np.array([normal_g[0], normal_g[1]])
    length = float(np.linalg.norm(along))
    if length < 1e-6:
        return head
    along /= length
    target = float(inside.max()) - head_radius  # the head's centre, inside the border
    centroid = float(inside.mean())
    # Moving by t along the floor changes the distance to the plane by t * length.
    return np.asarray(head, dtype=np.float64) + along * (target - centroid) / length


def border_window(
    center_c: np.ndarray,
    height: float,
    up: np.ndarray,
    intrinsics: Intrinsics,
    fill: float,
    side: int,
) -> np.ndarray:
    """The classifier window (homography, window to image pixels) at the person's scale,
    centred on the ``side`` border at the person's distance and height in the image."""
    on_border = np.array(
        [_border_slope(side, intrinsics) * float(center_c[2]), center_c[1], center_c[2]]
    )
    return level_window(on_border, height, up, intrinsics.K, fill)
