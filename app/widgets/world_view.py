"""The World 3D view: floor, cameras, their point clouds, the tracked people and (while the
skeleton stage runs) their skeletons, in OpenGL."""

from __future__ import annotations

import numpy as np
import pyqtgraph.opengl as gl
from PySide6.QtCore import Qt
from PySide6.QtGui import QColor, QFont, QMatrix4x4, QPainter, QVector3D, QVector4D
from PySide6.QtWidgets import QSizePolicy

from app.trails import TrailHistory, track_color
from app.widgets.overlay import Overlay
from optrack.calibration.overlap import BoardSuggestion
from optrack.geometry import camera_frustum
from optrack.skeleton.joints import PARENT
from optrack.types import NetworkCalibration, SkeletonBatch, TrackBatch

FRUSTUM_COLOR = (0.45, 0.75, 1.0, 1.0)
#: Where the calibration wizard suggests holding the board (region and outline).
GUIDANCE_COLOR = (0.3, 0.95, 0.35, 1.0)
# Frustum vertices: 0 is the optical centre, 1-4 the image corners at depth.
FRUSTUM_EDGES = np.array([0, 1, 0, 2, 0, 3, 0, 4, 1, 2, 2, 3, 3, 4, 4, 1])
# Where a camera may stand in the view's normalised coordinates (-1..1) once framed: its
# name is written to the right of it, so less room on that side.
FRAME_X = (-0.9, 0.6)
FRAME_Y = (-0.85, 0.85)
# A skeleton's bones: each joint to its parent (optrack/skeleton/joints.py).
BONES = tuple((joint, parent) for joint, parent in PARENT.items() if parent is not None)
JOINT_SIZE_PX = 7.0


def confidence_color(confidence: np.ndarray) -> np.ndarray:
    """RGBA per joint: red at confidence 0 through yellow to green at 1."""
    c = np.clip(np.asarray(confidence, dtype=np.float32), 0.0, 1.0)
    red = np.clip(2.0 - 2.0 * c, 0.0, 1.0)
    green = np.clip(2.0 * c, 0.0, 1.0)
    return np.column_stack([red, green, np.full_like(c, 0.1), np.ones_like(c)])


def _rgba(rgb: tuple[int, int, int], alpha: float = 1.0) -> tuple[float, float, float, float]:
    return (rgb[0] / 255, rgb[1] / 255, rgb[2] / 255, alpha)


class TaggedText(gl.GLTextItem):
    """A name in the 3D view on a dark tag, so that it reads over bright points too."""

    TAG = QColor(25, 28, 34, 200)

    def __init__(self, **kwargs) -> None:
        super().__init__(**kwargs)
        self.setDepthValue(10)  # painted after the clouds and meshes, never under them

    def paint(self) -> None:
        if not self.text:
            return
        self.setupGLState()
        anchor = self.compute_projection().map(QVector3D(*self.pos)).toPointF()
        point = self.align_text(anchor)
        painter = QPainter(self.view())
        painter.setFont(self.font)
        painter.setRenderHints(
            QPainter.RenderHint.Antialiasing | QPainter.RenderHint.TextAntialiasing
        )
        box = painter.fontMetrics().boundingRect(self.text).translated(point.toPoint())
        painter.setPen(Qt.PenStyle.NoPen)
        painter.setBrush(self.TAG)
        painter.drawRoundedRect(box.adjusted(-3, -1, 3, 1), 3, 3)
        painter.setPen(self.color)
        painter.drawText(point, self.text)
        painter.end()


class WorldView(gl.GLViewWidget):
    """3D view of the world frame (origin on the floor, z up, metres)."""

    def __init__(
        self,
        floor_size_m: float = 10.0,
        trail_seconds: float = 8.0,
        track_radius: float = 0.25,
        parent=None,
    ) -> None:
        super().__init__(parent)
        # Without Expanding a GLViewWidget collapses to zero width in a box layout.
        self.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Expanding)
        self.setMinimumSize(320, 240)
        self.setBackgroundColor((25, 28, 34))
        self.floor_size_m = floor_size_m
        self.setCameraPosition(distance=floor_size_m * 1.2, elevation=30, azimuth=-60)
        # Until the operator turns or zooms the view, it keeps every camera (and its name)
        # in sight: framed again when the cameras change and when the view is resized.
        self.user_moved = False
        self._camera_positions = np.zeros((0, 3))
        self.floor = gl.GLGridItem()
        self.floor.setSize(floor_size_m, floor_size_m)
        self.floor.setSpacing(1.0, 1.0)
        self.floor.setColor((150, 150, 160, 160))
        self.addItem(self.floor)
        self.axes = gl.GLAxisItem()
        self.axes.setSize(1.0, 1.0, 1.0)
        self.addItem(self.axes)
        self.overlay = Overlay(self)
        self.track_radius = track_radius
        self.trails = TrailHistory(trail_seconds)
        self._font = QFont()
        self._font.setPointSize(11)
        self._cylinder = gl.MeshData.cylinder(rows=1, cols=24, radius=[1.0, 1.0], length=1.0)
        self.cameras: dict[str, tuple[gl.GLLinePlotItem, gl.GLTextItem]] = {}
        self.clouds: dict[str, gl.GLScatterPlotItem] = {}
        self.people: dict[int, tuple[gl.GLMeshItem, gl.GLTextItem]] = {}
        self.trail_items: dict[int, gl.GLLinePlotItem] = {}
        # Skeletons: each track's bones (its colour) and joints (by confidence).
        self.skeletons: dict[int, tuple[gl.GLLinePlotItem, gl.GLScatterPlotItem]] = {}
        self.show_skeletons = True
        self._skeletons = SkeletonBatch(stamp=0.0)
        self.guidance_items: list = []  # where to hold the board next (calibration)

    # ---------------------------------------------------------------- cameras
    def set_calibration(self, calibration: NetworkCalibration, frustum_depth: float) -> None:
        """Draw each calibrated camera's viewing pyramid (``frustum_depth`` metres long)
        and its name; a camera without intrinsics is drawn as a point with its name."""
        for lines, label in self.cameras.values():
            self.removeItem(lines)
            self.removeItem(label)
        self.cameras.clear()
        for sensor_id, sensor in sorted(calibration.sensors.items()):
            pose = sensor.pose
            if sensor.intrinsics is not None and sensor.intrinsics.width:
                vertices = camera_frustum(sensor.intrinsics, pose, frustum_depth)
                lines = gl.GLLinePlotItem(
                    pos=vertices[FRUSTUM_EDGES], color=FRUSTUM_COLOR, width=2, mode="lines"
                )
            else:
                lines = gl.GLScatterPlotItem(pos=pose[None, :3, 3], color=FRUSTUM_COLOR, size=8)
            label = TaggedText(
                pos=pose[:3, 3] + (0.0, 0.0, 0.15), text=sensor_id, color=QColor(150, 200, 255)
            )
            label.setData(font=self._font)
            self.addItem(lines)
            self.addItem(label)
            self.cameras[sensor_id] = (lines, label)
        self._camera_positions = np.array(
            [sensor.pose[:3, 3] for sensor in calibration.sensors.values()]
        ).reshape(-1, 3)
        self.frame_cameras()

    # --------------------------------------------------------------- guidance
    def set_guidance(self, guidance: BoardSuggestion | None) -> None:
        """Where to hold the board next (the calibration wizard's advice, in this view's
        frame): the floor region in green and the board's outline at the suggested place;
        None (or no place found) clears them."""
        for item in self.guidance_items:
            self.removeItem(item)
        self.guidance_items = []
        if guidance is None or not guidance.found:
            return
        region = np.asarray(guidance.region, dtype=np.float64)
        if region.shape[1] == 2:
            region = guidance.floor_points()
        corners = np.vstack([guidance.corners, guidance.corners[:1]])
        self.guidance_items = [
            gl.GLScatterPlotItem(pos=region, color=GUIDANCE_COLOR[:3] + (0.35,), size=6),
            gl.GLLinePlotItem(pos=corners, color=GUIDANCE_COLOR, width=3, mode="line_strip"),
        ]
        for item in self.guidance_items:
            self.addItem(item)

    # ---------------------------------------------------------------- framing
    def _in_view(self, points: np.ndarray) -> bool:
        width, height = max(self.width(), 1), max(self.height(), 1)
        viewport = (0, 0, width, height)
        transform = self.projectionMatrix(viewport, viewport) * self.viewMatrix()
        for x, y, z in points:
            mapped = transform.map(QVector4D(float(x), float(y), float(z), 1.0))
            if mapped.w() <= 0:
                return False
            u, v = mapped.x() / mapped.w(), mapped.y() / mapped.w()
            if not (FRAME_X[0] < u < FRAME_X[1] and FRAME_Y[0] < v < FRAME_Y[1]):
                return False
        return True

    def frame_cameras(self) -> None:
        """Look at the middle of the cameras and the world's origin, from the floor view's
        usual distance or farther, until every camera stands inside the view with room
        for its name (nothing happens once the operator has moved the view)."""
        if self.user_moved or len(self._camera_positions) == 0:
            return
        points = np.vstack([self._camera_positions, np.zeros((1, 3))])
        low, high = points[:, :2].min(axis=0), points[:, :2].max(axis=0)
        middle = (low + high) / 2.0
        self.opts["center"] = QVector3D(float(middle[0]), float(middle[1]), 0.0)
        distance = self.floor_size_m * 1.2
        for _ in range(30):
            self.opts["distance"] = distance
            if self._in_view(self._camera_positions):
                break
            distance *= 1.1
        self.update()

    def resizeEvent(self, event) -> None:  # noqa: N802 (Qt's name)
        super().resizeEvent(event)
        self.frame_cameras()

    def mousePressEvent(self, event) -> None:  # noqa: N802
        self.user_moved = True
        super().mousePressEvent(event)

    def wheelEvent(self, event) -> None:  # noqa: N802
        self.user_moved = True
        super().wheelEvent(event)

    def set_cloud(self, sensor_id: str, points: np.ndarray, colors: np.ndarray | None) -> None:
        """Show a sensor's (already decimated) cloud: Nx3 world points, Nx3 RGB uint8 or None."""
        if colors is None:
            # Colour by height above the floor, so the floor and people stand apart.
            z = np.clip(points[:, 2] / 2.0, 0.0, 1.0)
            rgba = np.column_stack(
                [0.3 + 0.6 * z, 0.8 - 0.3 * z, 1.0 - 0.7 * z, np.full(len(z), 0.8)]
            )
        else:
            rgba = np.column_stack([colors[:, :3] / 255.0, np.full(len(colors), 0.9)])
        item = self.clouds.get(sensor_id)
        if item is None:
            item = gl.GLScatterPlotItem(size=2.0, pxMode=True)
            self.addItem(item)
            self.clouds[sensor_id] = item
        item.setData(pos=np.asarray(points, dtype=np.float32), color=rgba.astype(np.float32))

    # ----------------------------------------------------------------- people
    def set_batch(self, batch: TrackBatch) -> None:
        """Each track as a cylinder of its height, its id above it, its trail on the floor."""
        self.trails.update(batch)
        current = {t.id: t for t in batch.tracks}
        for track_id in list(self.people):
            if track_id not in current:
                mesh, label = self.people.pop(track_id)
                self.removeItem(mesh)
                self.removeItem(label)
        for track_id, track in current.items():
            if track_id not in self.people:
                mesh = gl.GLMeshItem(
                    meshdata=self._cylinder,
                    smooth=True,
                    shader="shaded",
                    color=_rgba(track_color(track_id)),
                )
                label = TaggedText(text=str(track_id), color=QColor(255, 255, 255))
                label.setData(font=self._font)
                self.addItem(mesh)
                self.addItem(label)
                self.people[track_id] = (mesh, label)
            mesh, label = self.people[track_id]
            transform = QMatrix4x4()
            transform.translate(track.x, track.y, 0.0)
            transform.scale(self.track_radius, self.track_radius, max(track.height, 0.01))
            mesh.setTransform(transform)
            label.setData(pos=(track.x, track.y, track.height + 0.2))
        trail_ids = set(self.trails.ids())
        for track_id in list(self.trail_items):
            if track_id not in trail_ids:
                self.removeItem(self.trail_items.pop(track_id))
        for track_id in trail_ids:
            trail = self.trails.trail(track_id)
            if len(trail) < 2:
                continue
            pos = np.column_stack([trail, np.full(len(trail), 0.02)])
            item = self.trail_items.get(track_id)
            if item is None:
                item = gl.GLLinePlotItem(color=_rgba(track_color(track_id)), width=2)
                self.addItem(item)
                self.trail_items[track_id] = item
            item.setData(pos=pos)

    # -------------------------------------------------------------- skeletons
    def set_show_skeletons(self, show: bool) -> None:
        """Draw the skeletons or not (the ``view.skeletons`` toggle)."""
        self.show_skeletons = bool(show)
        self.set_skeletons(self._skeletons)

    def set_skeletons(self, batch: SkeletonBatch) -> None:
        """Each skeleton's bones in its track's colour and its joints coloured by
        confidence; a lost skeleton (no joints) and one no longer sent are removed."""
        self._skeletons = batch
        shown = {s.id: s for s in batch.skeletons if s.joints} if self.show_skeletons else {}
        for track_id in [k for k in self.skeletons if k not in shown]:
            for item in self.skeletons.pop(track_id):
                self.removeItem(item)
        for track_id, skeleton in shown.items():
            if track_id not in self.skeletons:
                bones = gl.GLLinePlotItem(color=_rgba(track_color(track_id)), width=3, mode="lines")
                joints = gl.GLScatterPlotItem(size=JOINT_SIZE_PX, pxMode=True)
                bones.setDepthValue(5)
                joints.setDepthValue(6)  # over the bones and the person's cylinder
                self.addItem(bones)
                self.addItem(joints)
                self.skeletons[track_id] = (bones, joints)
            bones, joints = self.skeletons[track_id]
            pairs = [
                (skeleton.joints[a][:3], skeleton.joints[b][:3])
                for a, b in BONES
                if a in skeleton.joints and b in skeleton.joints
            ]
            bones.setData(pos=np.asarray(pairs, dtype=np.float32).reshape(-1, 3))
            values = np.asarray(list(skeleton.joints.values()), dtype=np.float32)
            joints.setData(pos=values[:, :3], color=confidence_color(values[:, 3]))
