"""Images of a printed checkerboard as a real camera sees it: known truth for the corner finder.

The synthetic sessions (``synthetic.py``) hand the solver projected corners;
this renders the pixels, so that the corner finder itself can be checked
against the truth. The board is drawn as it is printed and held: squares,
outer columns that may be cut short (OpenCV's sample board's are half a
square wide), a white paper margin, a clipboard frame and the room behind it.
Each pixel averages ``supersample``² rays through the camera's distortion
(area sampling, as a sensor integrates light), then the lens blur and the
sensor noise are added.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import cv2
import numpy as np

from optrack.calibration.board import Checkerboard

__all__ = ["PrintedBoard", "Replica", "opencv_sample_replica", "render_views"]


@dataclasses.dataclass(frozen=True)
class PrintedBoard:
    """A printed board; lengths in squares, from the outermost inner corners.

    ``cut`` is the width of the squares of the outermost columns (1: whole);
    ``margin`` the white paper left, right, top and bottom of the squares;
    ``frame`` the clipboard's width around the paper. The defaults are
    OpenCV's sample board (left*.jpg), measured on its rectified views.
    """

    board: Checkerboard
    cut: float = 0.5
    margin: tuple[float, float, float, float] = (0.2, 0.05, 0.1, 0.1)
    frame: float = 0.6
    black: float = 25.0
    white: float = 225.0
    frame_level: float = 80.0
    background: float = 110.0

    def shade(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Grey level at board coordinates ``u`` (along the columns) and ``v``, in squares."""
        cols, rows = self.board.cols - 1, self.board.rows - 1  # last inner corner
        left, right, top, bottom = self.margin
        x0, x1 = -self.cut, cols + self.cut
        y0, y1 = -1.0, rows + 1.0
        out = np.full(u.shape, self.background)
        out[
            (u > x0 - left - self.frame)
            & (u < x1 + right + self.frame)
            & (v > y0 - top - self.frame)
            & (v < y1 + bottom + self.frame)
        ] = self.frame_level
        out[(u > x0 - left) & (u < x1 + right) & (v > y0 - top) & (v < y1 + bottom)] = self.white
        squares = (u > x0) & (u < x1) & (v > y0) & (v < y1)
        out[squares & ((np.floor(u) + np.floor(v)) % 2 == 0)] = self.black
        return out


def _pixel_rays(
    camera: np.ndarray, dist: np.ndarray, size: tuple[int, int], supersample: int
) -> np.ndarray:
    """Undistorted normalised rays (N x 3) of each sub-pixel sample, row-major."""
    width, height = size
    offsets = (np.arange(supersample) + 0.5) / supersample - 0.5
    xs = (np.arange(width)[:, None] + offsets[None, :]).ravel()
    ys = (np.arange(height)[:, None] + offsets[None, :]).ravel()
    grid = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 1, 2)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12)
    normal = cv2.undistortPointsIter(grid, camera, dist, None, None, criteria).reshape(-1, 2)
    return np.column_stack([normal, np.ones(len(normal))])


def render_views(
    printed: PrintedBoard,
    camera: np.ndarray,
    dist: np.ndarray,
    size: tuple[int, int],
    poses: list[tuple[np.ndarray, np.ndarray]],
    *,
    supersample: int = 4,
    blur_px: float = 0.8,
    noise: float = 2.0,
    seed: int = 0,
) -> list[np.ndarray]:
    """8-bit grey images of ``printed`` seen from each (rvec, tvec) board-to-camera pose.

    ``camera`` and ``dist`` are OpenCV's camera matrix and distortion, ``size``
    is (width, height), translations are in metres (the board's square).
    """
    width, height = size
    rays = _pixel_rays(np.asarray(camera, float), np.asarray(dist, float), size, supersample)
    rng = np.random.default_rng(seed)
    images = []
    for rvec, tvec in poses:
        rotation, _ = cv2.Rodrigues(np.asarray(rvec, float).reshape(3))
        t = np.asarray(tvec, float).reshape(3)
        normal = rotation[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            depth = (normal @ t) / (rays @ normal)
        local = (depth[:, None] * rays - t) @ rotation / printed.board.square
        shade = printed.shade(local[:, 0], local[:, 1])
        shade[~(depth > 0)] = printed.background  # rays that miss the board's plane
        image = shade.reshape(height, supersample, width, supersample).mean(axis=(1, 3))
        if blur_px > 0:
            image = cv2.GaussianBlur(image, (0, 0), blur_px)
        image = image + rng.normal(0.0, noise, image.shape)
        images.append(np.clip(np.rint(image), 0, 255).astype(np.uint8))
    return images


@dataclasses.dataclass
class Replica:
    """Rendered views of a printed board with their truth."""

    board: Checkerboard
    camera: np.ndarray
    dist: np.ndarray
    size: tuple[int, int]
    images: list[np.ndarray]
    corners: list[np.ndarray]  # true corners per view, board order, pixels

    @property
    def fx(self) -> float:
        return float(self.camera[0, 0])

    def corner_errors(self, view: int, found: np.ndarray) -> np.ndarray:
        """Each corner found in ``view``: its distance (px) to the nearest true corner (a
        finder may number the corners from another end of the board)."""
        truth = self.corners[view]
        return np.linalg.norm(found[:, None] - truth[None], axis=2).min(axis=1)


def opencv_sample_replica(folder: Path, supersample: int = 4) -> Replica:
    """OpenCV's sample board (9x6, 25 mm, outer columns cut to half a square) seen through
    the camera, distortion and 13 board poses of OpenCV's own calibration of its left*.jpg
    (``folder``/left_intrinsics.yml): views like the real ones whose true fx is OpenCV's."""
    path = Path(folder) / "left_intrinsics.yml"
    if not path.is_file():
        raise FileNotFoundError(f"OpenCV's left_intrinsics.yml is not in {folder}.")
    stored = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    try:
        camera = stored.getNode("camera_matrix").mat()
        dist = stored.getNode("distortion_coefficients").mat().ravel()
        poses = [(row[:3], row[3:]) for row in stored.getNode("extrinsic_parameters").mat()]
        size = (
            int(stored.getNode("image_width").real()),
            int(stored.getNode("image_height").real()),
        )
    finally:
        stored.release()
    board = Checkerboard(9, 6, 0.025)
    images = render_views(PrintedBoard(board), camera, dist, size, poses, supersample=supersample)
    corners = [
        cv2.projectPoints(board.object_points, r, t, camera, dist)[0][:, 0] for r, t in poses
    ]
    return Replica(board, camera, dist, size, images, corners)
