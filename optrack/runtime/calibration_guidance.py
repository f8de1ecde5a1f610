"""Where the operator holds the board next: the live calibration's guidance.

While a camera is not calibrated yet (extrinsics), :class:`BoardGuide` finds
where it and a calibrated camera both see the board whole (and, once every camera
is calibrated, where a camera that shares fewer board poses than
``calibration_live.min_shared_poses`` gets another one, away from those it has:
"kinect2_5: 1 of 2 shared views; stand at about ...")
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
from optrack.geometry import invert, transform_points
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
        """``state`` with the guidance (extrinsics, once some camera is calibrated): for its
        first camera not calibrated yet, else for the first calibrated one that shares
        fewer board poses than it needs (:attr:`SensorLive.settled`: a place away from
        those it shares, the sentence saying how many it has); else unchanged."""
        if state.phase != "extrinsics":
            return state
        calibrated = sorted(s for s, v in state.sensors.items() if v.calibrated)
        missing = sorted(s for s, v in state.sensors.items() if not v.calibrated)
        short = sorted(s for s, v in state.sensors.items() if v.calibrated and not v.settled)
        if not calibrated or not (missing or short):
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
        partners = [s for s in calibrated if s in views]
        if missing:
            key: tuple = (tuple(calibrated), tuple(missing), tuple(sorted(views)))
        else:
            key = (tuple(calibrated), tuple(sorted(views)), self._shared_key(state, short))
        if self._cache is not None and self._cache[0] == key:
            guidance = self._cache[1]
        elif missing:
            guidance = self._suggest(views, missing, partners)
            self._cache = (key, guidance)
        else:
            guidance = self._further(state, views, short, partners)
            self._cache = (key, guidance)
        if guidance is None and not missing:  # no rough poses: the count, no place
            live = state.sensors[short[0]]
            guidance = BoardSuggestion(
                short[0],
                (),
                np.zeros((0, 2)),
                np.zeros(3),
                np.zeros(3),
                shared=(live.shared_poses, live.shared_needed),
            )
        if guidance is None:
            return state
        if guidance.found:  # the solved frame from the rough one, by the calibrated partner
            frame_T_world = self._frame(state, views, guidance.partners[0])
            if frame_T_world is not None:
                guidance = dataclasses.replace(guidance, frame_T_world=frame_T_world)
        return dataclasses.replace(state, guidance=guidance, message=guidance.sentence())

    @staticmethod
    def _frame(state: LiveState, views: dict[str, SensorView], sensor: str) -> np.ndarray | None:
        """The live calibration's frame from the rough one, by a calibrated ``sensor``."""
        solved = state.sensors[sensor].world_T_camera
        if solved is None or sensor not in views:
            return None
        return solved @ invert(views[sensor].world_T_camera)

    @staticmethod
    def _shared_key(state: LiveState, short: list[str]) -> tuple:
        """What the advice for cameras short of shared poses depends on."""
        return tuple(
            (s, state.sensors[s].shared_poses, state.sensors[s].shared_needed) for s in short
        )

    def _further(
        self, state: LiveState, views: dict[str, SensorView], short: list[str], partners: list[str]
    ) -> BoardSuggestion | None:
        """For the first calibrated camera short of shared board poses that has a place:
        one with another calibrated camera, away from the poses it shares; else the first
        one's sentence without a place (None when none has a rough pose)."""
        first: BoardSuggestion | None = None
        for sensor in short:
            live = state.sensors[sensor]
            frame_T_world = self._frame(state, views, sensor)
            if frame_T_world is None:
                continue
            avoid = None
            if live.shared_centers is not None and len(live.shared_centers):
                avoid = transform_points(invert(frame_T_world), live.shared_centers)
            others = [s for s in partners if s != sensor]
            suggestion = suggest_board(views, sensor, others, self.board, self.params, avoid)
            suggestion = dataclasses.replace(
                suggestion, shared=(live.shared_poses, live.shared_needed)
            )
            if suggestion.found:
                return suggestion
            first = first or suggestion
        return first

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
