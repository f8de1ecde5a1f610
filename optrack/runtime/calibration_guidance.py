"""Where the operator holds the board next: the live calibration's guidance.

While a camera is not calibrated yet (extrinsics), :class:`BoardGuide` finds
where it and a calibrated camera both see the board whole
(:func:`optrack.calibration.overlap.suggest_board`, the maths the simulated
operator plans with) and puts it in the wizard's state: the sentence ("For
kinect2_1: stand at about (1.2, -0.4) ... facing kinect2_1 and kinect2_0")
and the place (``LiveState.guidance``) the views draw. The cameras' rough
poses are those their detector nodes use (their previews carry them: a stored
calibration, or the pose the sensor reports), all in one world frame; a
camera whose node has none gets the plain sentence.
"""

from __future__ import annotations

import dataclasses
import threading

import numpy as np

from optrack.calibration.board import Checkerboard
from optrack.calibration.live import LiveState
from optrack.calibration.overlap import (
    GUIDANCE_PARAMS,
    BoardSuggestion,
    SensorView,
    suggest_board,
)
from optrack.geometry import invert
from optrack.net.messages import PreviewMessage
from optrack.params import Params

__all__ = ["BoardGuide"]


class BoardGuide:
    """The rough poses of a site's cameras (from their previews) and the advice."""

    def __init__(self, board: Checkerboard, params: Params | None = None) -> None:
        self.board = board
        self.params = params if params is not None else GUIDANCE_PARAMS.create()
        self._lock = threading.Lock()
        self.poses: dict[str, np.ndarray] = {}
        self._cache: tuple[tuple, BoardSuggestion | None] | None = None

    def on_preview(self, message: PreviewMessage, key: str) -> None:
        """A preview's camera pose (a bus callback: the caller subscribes)."""
        if message.world_T_camera is not None:
            self.set_pose(message.sensor, np.asarray(message.world_T_camera))

    def set_pose(self, sensor: str, world_T_camera: np.ndarray) -> None:
        """A camera's rough pose (what a preview says)."""
        with self._lock:
            self.poses[sensor] = np.asarray(world_T_camera, dtype=np.float64)

    def advise(self, state: LiveState) -> LiveState:
        """``state`` with the guidance for its first camera not calibrated yet (extrinsics,
        once some camera is calibrated): the place and the sentence; else unchanged."""
        if state.phase != "extrinsics":
            return state
        calibrated = sorted(s for s, v in state.sensors.items() if v.calibrated)
        missing = sorted(s for s, v in state.sensors.items() if not v.calibrated)
        if not calibrated or not missing:
            return state
        with self._lock:
            poses = dict(self.poses)
        views = {
            s: SensorView(
                poses[s],
                live.intrinsics,
                float(self.params.min_range),
                float(self.params.max_range),
            )
            for s, live in state.sensors.items()
            if s in poses and live.intrinsics is not None
        }
        key = (tuple(calibrated), tuple(missing), tuple(sorted(views)))
        if self._cache is not None and self._cache[0] == key:
            guidance = self._cache[1]
        else:
            guidance = self._suggest(views, missing, [s for s in calibrated if s in views])
            self._cache = (key, guidance)
        if guidance is None:
            return state
        if guidance.found:  # the solved frame from the rough one, by the calibrated partner
            partner = guidance.partners[0]
            solved = state.sensors[partner].world_T_camera
            if solved is not None:
                frame_T_world = solved @ invert(views[partner].world_T_camera)
                guidance = dataclasses.replace(guidance, frame_T_world=frame_T_world)
        return dataclasses.replace(state, guidance=guidance, message=guidance.sentence())

    def _suggest(
        self, views: dict[str, SensorView], missing: list[str], calibrated: list[str]
    ) -> BoardSuggestion | None:
        """The first missing camera with a place; else the first one's 'no place' (None
        when no missing camera has a rough pose, or no calibrated one has)."""
        first: BoardSuggestion | None = None
        if not calibrated:
            return None
        for sensor in missing:
            if sensor not in views:
                continue
            suggestion = suggest_board(views, sensor, calibrated, self.board, self.params)
            if suggestion.found:
                return suggestion
            first = first or suggestion
        return first
