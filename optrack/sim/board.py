"""The printed calibration checkerboard as a thing in the simulated world.

The pattern's geometry (inner corners, square size, board frame) is
:class:`optrack.calibration.board.Checkerboard`'s; this adds what the
renderer needs: a thin box with a white margin around the printed squares,
its materials, and the printed face's reflectance. Board frame (as
:class:`~optrack.recording.BoardTruth`): origin at the first inner corner, x
along the ``cols`` inner corners, y along the ``rows``, z into the board, so
the printed face looks along -z and a camera seeing the face sees x to the
right and y down (OpenCV's object-point convention). The printed area holds
(cols + 1) x (rows + 1) squares, the square at (-1, -1) black, inside a white
margin.

The operator who carries it (:mod:`optrack.sim.board_operator`) walks it
through placements planned so that every sensor, and then every neighbouring
pair of sensors, sees the whole board at a usable resolution, and lays it on
the floor at several places (:mod:`optrack.sim.board_plan`; OpenPTrack's
network calibration procedure, Munaro et al. 2016, section 3). Both read
their settings from :data:`BOARD_PARAMS`.
"""

from __future__ import annotations

import numpy as np
import open3d as o3d

from optrack.calibration.board import Checkerboard
from optrack.calibration.overlap import PLACEMENT_PARAMS
from optrack.params import Param, Params, Schema, register
from optrack.sim.materials import Material
from optrack.sim.scenario import BoardSpec

__all__ = ["BOARD_PARAMS", "PhysicalBoard"]

BACK_ALBEDO, BACK_INFRARED = (0.3, 0.3, 0.3), 0.3  # the unprinted back and edges

BOARD_PARAMS = register(
    Schema(
        "sim_board",
        [
            Param(
                "margin_squares",
                0.8,
                0.2,
                3.0,
                0.1,
                "squares",
                "White border around the printed squares.",
            ),
            Param("thickness", 0.006, 0.001, 0.05, 0.001, "m", "Board thickness."),
            Param("white", 0.85, 0.3, 1.0, 0.01, "", "Albedo of the white squares (colour)."),
            Param("black", 0.04, 0.0, 0.3, 0.01, "", "Albedo of the black squares (colour)."),
            Param(
                "white_infrared", 0.8, 0.1, 1.0, 0.01, "", "Infrared albedo of the white squares."
            ),
            Param(
                "black_infrared",
                0.05,
                0.0,
                0.5,
                0.01,
                "",
                "Infrared albedo of the black squares (toner absorbs near infrared).",
            ),
            Param(
                "grip_depth",
                0.04,
                0.0,
                0.3,
                0.01,
                "m",
                "Hands hold the board this far behind its face.",
            ),
            Param("carry_height", 1.15, 0.5, 2.0, 0.05, "m", "Board centre height while walking."),
            Param(
                "carry_distance", 0.4, 0.2, 1.0, 0.05, "m", "Board centre in front of the operator."
            ),
            *PLACEMENT_PARAMS,  # optrack.calibration.overlap
            Param(
                "square_px_wanted",
                16.0,
                3.0,
                80.0,
                0.5,
                "px",
                "Square size (pixels) a spot aims for.",
            ),
            Param(
                "floor_square_px_min",
                6.0,
                2.0,
                50.0,
                0.5,
                "px",
                "Smallest square size seen on the floor.",
            ),
            Param(
                "floor_max_incidence_deg",
                65.0,
                10.0,
                85.0,
                1.0,
                "deg",
                "Largest angle between a board on the floor and a sensor.",
            ),
            Param(
                "wall_clearance",
                0.5,
                0.0,
                3.0,
                0.05,
                "m",
                "Candidate spots keep this far from the walls.",
            ),
            Param(
                "spot_clearance",
                0.3,
                0.0,
                1.0,
                0.01,
                "m",
                "Free space around the operator's spots, beyond the body.",
            ),
            Param(
                "height_preference",
                0.01,
                0.0,
                1.0,
                0.01,
                "1/m",
                "Score lost per metre away from the carrying height.",
            ),
            Param(
                "floor_spacing",
                1.5,
                0.3,
                10.0,
                0.1,
                "m",
                "Minimum distance between floor placements.",
            ),
            Param(
                "step_aside",
                1.0,
                0.5,
                3.0,
                0.1,
                "m",
                "Where the operator stands beside a board on the floor.",
            ),
            Param(
                "raise_seconds",
                1.0,
                0.1,
                10.0,
                0.1,
                "s",
                "Time to turn and raise the board at a spot.",
            ),
            Param(
                "hold_seconds",
                2.5,
                0.2,
                30.0,
                0.1,
                "s",
                "Time the board is held still at each spot.",
            ),
            Param(
                "lay_seconds", 1.2, 0.1, 10.0, 0.1, "s", "Time to lay the board down or pick it up."
            ),
            Param("sway_m", 0.003, 0.0, 0.05, 0.001, "m", "Hand tremor while holding the board."),
            Param("operator_speed", 0.9, 0.2, 2.0, 0.05, "m/s", "The operator's walking speed."),
        ],
        help="The calibration checkerboard and the operator carrying it.",
    )
)


class PhysicalBoard:
    """A printed :class:`~optrack.calibration.board.Checkerboard` (``pattern``) on a thin
    box: its mesh (board frame), materials and printed reflectance."""

    def __init__(self, pattern: Checkerboard, params: Params | None = None) -> None:
        self.pattern = pattern
        self.params = params if params is not None else BOARD_PARAMS.create()
        margin = float(self.params.margin_squares)
        s = pattern.square
        self.lo = np.array([-(1 + margin) * s, -(1 + margin) * s])
        self.hi = np.array([(pattern.cols + margin) * s, (pattern.rows + margin) * s])
        size = np.append(self.hi - self.lo, float(self.params.thickness))
        box = o3d.geometry.TriangleMesh.create_box(*size)
        self.vertices = np.asarray(box.vertices) + np.append(self.lo, 0.0)
        self.triangles = np.asarray(box.triangles)
        front = np.all(np.abs(self.vertices[self.triangles][:, :, 2]) < 1e-9, axis=1)
        self.triangle_front = front  # the printed face (z = 0)
        p = self.params
        self.materials = [
            Material("board_face", (p.white,) * 3, p.white_infrared, checker=True),
            Material("board_back", BACK_ALBEDO, BACK_INFRARED),
        ]

    @classmethod
    def from_spec(cls, spec: BoardSpec, params: Params | None = None) -> PhysicalBoard:
        """The board a scenario's operator carries."""
        return cls(Checkerboard(spec.cols, spec.rows, float(spec.square)), params)

    @property
    def center(self) -> np.ndarray:
        """Centre of the inner-corner grid in the board frame."""
        return self.pattern.center

    @property
    def outline(self) -> np.ndarray:
        """The four outer corners of the printed squares, board frame, (4, 3)."""
        s, cols, rows = self.pattern.square, self.pattern.cols, self.pattern.rows
        x0, y0, x1, y1 = -s, -s, cols * s, rows * s
        return np.array([[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0]], dtype=np.float64)

    def reflectance(self, board_xy: np.ndarray, footprint: np.ndarray) -> np.ndarray:
        """Fraction of white (0 black .. 1 white) seen by pixels at board points (N, 2)
        whose footprint on the board is ``footprint`` metres wide.

        The pattern is box-filtered over the footprint analytically (the filtered
        checkerboard of I. Quilez, iquilezles.org/articles/checkerfiltering), so that
        corners render with sub-pixel accuracy instead of staircases.
        """
        square = self.pattern.square
        u = board_xy[:, 0] / square
        v = board_xy[:, 1] / square
        w = np.clip(footprint / square, 1e-3, 2.0)

        def square_wave(x: np.ndarray) -> np.ndarray:
            def tri(y: np.ndarray) -> np.ndarray:
                return np.abs(np.mod(y * 0.5, 1.0) - 0.5)

            return 2.0 * (tri(x - 0.5 * w) - tri(x + 0.5 * w)) / w

        value = 0.5 - 0.5 * square_wave(u) * square_wave(v)
        printed = (u >= -1.0) & (u <= self.pattern.cols) & (v >= -1.0) & (v <= self.pattern.rows)
        return np.where(printed, value, 1.0).astype(np.float32)
