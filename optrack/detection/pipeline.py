"""The per-sensor people detector: OpenPTrack's ground-based cascade.

One :class:`PeopleDetector` per sensor composes the stages (Munaro et al.
2012 section 3; OpenPTrack, Munaro et al. 2016 section 4.2)::

    depth -> valid, in range, subsampled points -> [denoise]
          -> ground plane (initialised once from the voxelised cloud)
          -> floor removal, floor refit (unless locked) -> voxel grid
          -> [background subtraction] -> ground frame -> Euclidean clusters
          -> head-based sub-clusters -> height / width / head checks
          -> HOG confidence (colour, infrared, or the trained depth classifier
             when dark) -> DetectionBatch

Positions are in the world frame when the sensor's ``world_T_camera`` is
known (``frame_id = "world"``), else in the sensor's ground frame
(``frame_id = "ground"``: origin on the floor under the camera, z up, x
along the camera's x); ``camera_xyz`` is always the camera-frame centroid.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np

from optrack.detection.background import BackgroundModel
from optrack.detection.classifier import (
    HogClassifier,
    equalised_infrared,
    hsv_histogram,
    level_window,
    luminance,
    person_window,
    window_footprint,
)
from optrack.detection.clustering import Candidate, TallColumns, person_candidates
from optrack.detection.depth_classifier import (
    DepthClassifier,
    default_depth_classifier,
    relative_depth,
)
from optrack.detection.edge import border_window, corrected_head, lateral_cut
from optrack.detection.flags import is_occluded, outside_fraction
from optrack.detection.ground import (
    FIT_POINTS,
    GroundEstimator,
    GroundStore,
    check_ground,
    ground_from_calibration,
    ground_T_camera,
)
from optrack.detection.params import detection_params
from optrack.detection.preprocessing import (
    OrganisedCloud,
    denoise,
    select_points,
    split_at_floor,
    voxel_grid,
)
from optrack.geometry import Plane, invert, project
from optrack.params import Params
from optrack.types import Detection, DetectionBatch, Intrinsics, RGBDFrame

__all__ = ["Judgement", "PeopleDetector"]

#: Rows of a candidate's window sampled for its pixels (silhouette, histogram, occlusion):
#: half the HOG window's 128, which the silhouette is upsampled from.
CROP_ROWS = 64


def _transform_xyz(
    a_T_b: np.ndarray, x: np.ndarray, y: np.ndarray, z: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``a_T_b`` applied to points given as their x, y and z arrays, element-wise (a BLAS
    product on a tall Nx3 array is many times slower, and slower still on a busy
    machine); the result in the same form, in the dtype of ``a_T_b`` and the arrays."""
    r, t = a_T_b[:3, :3], a_T_b[:3, 3]
    return tuple(x * r[k, 0] + y * r[k, 1] + z * r[k, 2] + t[k] for k in range(3))  # type: ignore[return-value]


def _transform(a_T_b: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``a_T_b`` applied to ...x3 points (see :func:`_transform_xyz`)."""
    return np.stack(_transform_xyz(a_T_b, points[..., 0], points[..., 1], points[..., 2]), axis=-1)


class _Crop(NamedTuple):
    """A candidate's strided window: camera and ground coordinates, valid and own pixels."""

    camera: tuple[np.ndarray, ...]
    ground: tuple[np.ndarray, ...]
    valid: np.ndarray
    mask: np.ndarray


class _Window(NamedTuple):
    """A candidate's classifier window: the person's centre (camera frame) and height, the
    window's homography to the image, the image pixels it covers and the crop's stride."""

    center: np.ndarray
    height: float
    to_image: np.ndarray
    footprint: tuple[int, int, int, int]
    stride: int


@dataclasses.dataclass
class Judgement:
    """What the detector made of one candidate (kept for inspection and tests)."""

    candidate: Candidate
    confidence: float
    source: str  # "color", "infrared" or "depth"
    accepted: bool
    detection: Detection
    #: Judged on depth: its windows (silhouette, and relative depth for the trained
    #: depth classifier), the full-body one first.
    windows: list[tuple[np.ndarray, np.ndarray | None]] = dataclasses.field(default_factory=list)


class PeopleDetector:
    """People detection for one sensor, frame after frame.

    ``ground`` fixes the floor (camera frame, a,b,c,d); without it the floor
    is estimated from the first usable frame (see
    :class:`~optrack.detection.ground.GroundEstimator`), combined with the
    calibration's floor when ``world_T_camera`` is given. ``depth_model`` is a
    depth classifier to use instead of the file the ``depth_model`` parameter names.
    """

    def __init__(
        self,
        params: Params | None = None,
        *,
        sensor_id: str = "sensor",
        ground: Plane | Sequence[float] | None = None,
        world_T_camera: np.ndarray | None = None,
        ground_store: GroundStore | None = None,
        depth_model: DepthClassifier | None = None,
    ) -> None:
        self.params = params if params is not None else detection_params()
        self.sensor_id = sensor_id
        self.world_T_camera = (
            np.asarray(world_T_camera, dtype=np.float64) if world_T_camera is not None else None
        )
        calibration = None
        if self.world_T_camera is not None:
            calibration = ground_from_calibration(self.world_T_camera)
        self.ground = GroundEstimator(
            self.params,
            plane=check_ground(ground) if ground is not None else None,
            calibration=calibration,
            store=ground_store,
            sensor_id=sensor_id,
        )
        self.background = BackgroundModel(
            float(self.params.background_resolution), float(self.params.background_seconds)
        )
        self.hog = HogClassifier()
        #: The trained depth classifier, instead of the one ``depth_model`` names.
        self.depth_model = depth_model
        self.last_judgements: list[Judgement] = []
        self.last_luminance: float | None = None

    # ------------------------------------------------------------------ inputs
    def process(self, frame: RGBDFrame) -> DetectionBatch:
        """Detect people in one frame of this sensor."""
        return self._run(
            OrganisedCloud.from_frame(frame),
            stamp=frame.timestamp,
            seq=frame.seq,
            color=frame.color,
            color_intrinsics=frame.color_intrinsics,
            infrared=frame.infrared,
            confidence=frame.confidence,
        )

    def process_cloud(
        self,
        points: np.ndarray,
        intrinsics: Intrinsics,
        color: np.ndarray | None = None,
        stamp: float = 0.0,
        seq: int = 0,
    ) -> DetectionBatch:
        """Detect people in an organised cloud (HxWx3 camera frame, NaN invalid), as PCL."""
        return self._run(
            OrganisedCloud(intrinsics, points=points), stamp=stamp, seq=seq, color=color
        )

    def relearn_background(self) -> None:
        """Learn the background again from the next frames (and enable subtraction)."""
        self.params.update({"background_subtraction": True})
        self.background = BackgroundModel(
            float(self.params.background_resolution), float(self.params.background_seconds)
        )

    # ---------------------------------------------------------------- pipeline
    def _run(
        self,
        cloud: OrganisedCloud,
        stamp: float,
        seq: int,
        color: np.ndarray | None = None,
        color_intrinsics: Intrinsics | None = None,
        infrared: np.ndarray | None = None,
        confidence: np.ndarray | None = None,
    ) -> DetectionBatch:
        started = time.perf_counter()
        self.last_judgements = []
        frame_id = "world" if self.world_T_camera is not None else "ground"

        def batch(detections: list[Detection]) -> DetectionBatch:
            plane = self.ground.plane
            return DetectionBatch(
                sensor_id=self.sensor_id,
                stamp=stamp,
                seq=seq,
                frame_id=frame_id,
                detections=detections,
                ground=tuple(plane.to_list()) if plane is not None else None,  # type: ignore[arg-type]
                processing_ms=(time.perf_counter() - started) * 1000.0,
                voxel_size=float(self.params.voxel_size),
            )

        points = self._above_floor(cloud, confidence)
        if points is None:
            return batch([])
        plane = self.ground.plane
        assert plane is not None
        g_T_c = ground_T_camera(plane)
        candidates = self._candidates(points, g_T_c, stamp)
        if not candidates:
            return batch([])

        image, image_intrinsics, source = self._hog_image(
            cloud.intrinsics, color, color_intrinsics, infrared
        )
        c_T_g = invert(g_T_c)
        out: list[Detection] = []
        for candidate in candidates:
            judgement = self._judge(
                candidate,
                cloud,
                g_T_c,
                c_T_g,
                image,
                image_intrinsics,
                source,
                color,
                color_intrinsics or cloud.intrinsics,
            )
            self.last_judgements.append(judgement)
            if judgement.accepted:
                out.append(judgement.detection)
        return batch(out)

    def _above_floor(
        self, cloud: OrganisedCloud, confidence: np.ndarray | None
    ) -> np.ndarray | None:
        """The points between the floor and a person's top (camera frame), the floor
        refit on the way; None while the floor is not yet known."""
        p = self.params
        s = int(p.sampling_factor)
        top = float(p.max_height) + float(p.cluster_tolerance) * float(p.voxel_size)
        floor_distance = float(p.ground_inlier_distance)
        if p.apply_denoising or not self.ground.ready:
            points, sampled = select_points(
                cloud, s, float(p.max_distance), confidence, float(p.confidence_threshold)
            )
            if p.apply_denoising:
                points = denoise(points, int(p.mean_k_denoising), float(p.std_dev_denoising))
            if not self.ground.ready:
                voxels = voxel_grid(points, float(p.voxel_size))
                if not self.ground.initialise(voxels, len(points) / max(sampled, 1)):
                    return None
            # Floor removal before the voxel grid (the same points go as after it, and
            # the floor, most of a frame, is not voxelised), and the floor refit on them.
            heights = self.ground.update(points)
            above = (heights > floor_distance) & (heights < top)
            return np.compress(above, points, axis=0)
        # the same in one pass over the depth image, before making points
        assert self.ground.plane is not None
        points, floor, count = split_at_floor(
            cloud,
            s,
            float(p.max_distance),
            self.ground.plane.coefficients,
            floor_distance,
            top,
            FIT_POINTS,
            confidence,
            float(p.confidence_threshold),
        )
        self.ground.refit(floor, count)
        return points

    def _candidates(self, points: np.ndarray, g_T_c: np.ndarray, stamp: float) -> list[Candidate]:
        """People candidates among the points above the floor (ground frame voxels)."""
        p = self.params
        voxel = float(p.voxel_size)
        if p.background_subtraction:  # PCL's order: the background goes before the walls
            foreground = voxel_grid(points, voxel)
            if self.background.learning and self.background.learn(foreground, stamp):
                pass  # still learning: this frame is detected without subtraction
            else:
                foreground = foreground[self.background.foreground(foreground)]
            return person_candidates(_transform(g_T_c, foreground), p)
        # Walls and cupboards (tall columns, most of the points) are found on the
        # points and left out before the voxel grid, not voxelised and then dropped.
        columns = TallColumns.from_camera(
            points, g_T_c, voxel, float(p.max_height), float(p.cluster_tolerance) * voxel
        )
        foreground = voxel_grid(points, voxel, skip=columns.in_tall)
        voxels = _transform(g_T_c, foreground)
        return person_candidates(voxels, p, touching=columns.near(voxels))

    def _hog_image(
        self,
        intrinsics: Intrinsics,
        color: np.ndarray | None,
        color_intrinsics: Intrinsics | None,
        infrared: np.ndarray | None,
    ) -> tuple[np.ndarray | None, Intrinsics, str]:
        """The image HOG runs on, its intrinsics, and the confidence source.

        Colour when bright enough (OpenPTrack's luminance gate), else the
        equalised infrared image when there is one, else the depth silhouette.
        """
        p = self.params
        self.last_luminance = None
        if p.use_rgb and p.hog_image in ("auto", "color") and color is not None:
            self.last_luminance = luminance(color)
            if self.last_luminance >= float(p.minimum_luminance):
                return color, color_intrinsics or intrinsics, "color"
        if p.use_rgb and p.hog_image in ("auto", "infrared") and infrared is not None:
            return equalised_infrared(infrared), intrinsics, "infrared"
        return None, intrinsics, "depth"

    def _judge(
        self,
        candidate: Candidate,
        cloud: OrganisedCloud,
        g_T_c: np.ndarray,
        c_T_g: np.ndarray,
        image: np.ndarray | None,
        image_intrinsics: Intrinsics,
        source: str,
        color: np.ndarray | None,
        color_intrinsics: Intrinsics,
    ) -> Judgement:
        p = self.params
        plane = self.ground.plane
        assert plane is not None
        height = candidate.height
        head = self._head(candidate, c_T_g, cloud.intrinsics)
        # Head top, floor and centre on the person's axis, camera frame.
        up_c = c_T_g[:3, 2]
        bottom_c = c_T_g[:3, 0] * float(head[0]) + c_T_g[:3, 1] * float(head[1]) + c_T_g[:3, 3]
        top_c, center_c = bottom_c + up_c * height, bottom_c + up_c * (height / 2.0)
        pixels, _ = project(np.stack([top_c, bottom_c, center_c]), cloud.intrinsics)
        fill = float(p.hog_window_fill)
        to_depth = level_window(center_c, height, plane.normal, cloud.intrinsics.K, fill)
        person_px = abs(float(pixels[1][1] - pixels[0][1]))
        window = _Window(
            center_c, height, to_depth, window_footprint(to_depth, cloud.shape),
            max(1, round(person_px / fill / CROP_ROWS)),
        )  # fmt: skip
        score, crop, windows = self._score(
            head, window, cloud, g_T_c, image, image_intrinsics, source
        )
        threshold = p.min_confidence
        if source == "depth":
            trained = p.depth_classifier == "trained"
            threshold = p.min_depth_model_confidence if trained else p.min_depth_confidence
        accepted = score > float(threshold)

        # Flags and histogram, of accepted candidates only (the others are not output).
        out_of_view = outside_fraction(pixels, person_px, cloud.shape) > float(
            p.out_of_view_fraction
        )
        occluded = False
        histogram: list[float] = []
        if accepted:
            if crop is None:
                crop = self._crop(head, height, cloud, g_T_c, window.footprint, window.stride)
            occluded = is_occluded(
                p,
                crop.ground,
                crop.valid,
                (float(head[0]), float(head[1])),
                pixels,
                window.footprint[:2],
                window.stride,
                cloud.intrinsics,
                float(center_c[2]),
            )
            histogram = self._histogram(
                crop, color, color_intrinsics, cloud, window.footprint, window.stride
            )
        detection = Detection(
            height=float(height),
            confidence=score,
            box=self._box(pixels, person_px, cloud.shape),
            occluded=bool(occluded),
            out_of_view=bool(out_of_view),
            histogram=histogram,
            **self._position(center_c, g_T_c),
        )
        return Judgement(candidate, score, source, accepted, detection, windows)

    def _head(self, candidate: Candidate, c_T_g: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
        """Where the candidate stands (ground frame x, y): its head centroid, moved out for
        a head cut by the image's left or right border (:mod:`optrack.detection.edge`)."""
        p = self.params
        if not p.edge_window:
            return candidate.head
        center = c_T_g[:3, :3] @ candidate.center + c_T_g[:3, 3]
        side = lateral_cut(center, candidate.height, intrinsics)
        if side == 0:
            return candidate.head
        return corrected_head(
            candidate.points,
            candidate.height,
            candidate.head,
            side,
            c_T_g,
            intrinsics,
            float(p.head_fraction),
            float(p.edge_head_radius),
            float(p.voxel_size),
        )

    def _score(
        self,
        head: np.ndarray,
        window: _Window,
        cloud: OrganisedCloud,
        g_T_c: np.ndarray,
        image: np.ndarray | None,
        image_intrinsics: Intrinsics,
        source: str,
    ) -> tuple[float, _Crop | None, list[tuple[np.ndarray, np.ndarray | None]]]:
        """The candidate's confidence (and its crop and windows when judged on depth): the
        score of its full-body window; for a person cut by the image's left or right
        border, the better of that and the score of the window on the border, mirrored
        there (its visible part judged)."""
        p = self.params
        plane = self.ground.plane
        assert plane is not None
        fill = float(p.hog_window_fill)
        center_c, height = window.center, window.height
        if source == "depth":
            crop = self._crop(head, height, cloud, g_T_c, window.footprint, window.stride)
            windows = [self._depth_windows(crop, window.to_image, window, False)]
            side = lateral_cut(center_c, height, cloud.intrinsics) if p.edge_window else 0
            if side:
                to_border = border_window(
                    center_c, height, plane.normal, cloud.intrinsics, fill, side
                )
                footprint = window_footprint(to_border, cloud.shape)
                border_crop = self._crop(head, height, cloud, g_T_c, footprint, window.stride)
                border = window._replace(to_image=to_border, footprint=footprint)
                windows.append(self._depth_windows(border_crop, to_border, border, True))
            if p.depth_classifier == "trained":
                model = self.depth_model or default_depth_classifier(str(p.depth_model))
                return max(model.score(*pair) for pair in windows), crop, windows  # type: ignore[arg-type]
            return max(self.hog.score(pair[0]) for pair in windows), crop, windows
        assert image is not None
        to_image = (
            window.to_image
            if image_intrinsics is cloud.intrinsics
            else level_window(center_c, height, plane.normal, image_intrinsics.K, fill)
        )
        score = self.hog.score(person_window(image, to_image))
        side = lateral_cut(center_c, height, image_intrinsics) if p.edge_window else 0
        if side:
            to_border = border_window(center_c, height, plane.normal, image_intrinsics, fill, side)
            score = max(score, self.hog.score(person_window(image, to_border, mirror=True)))
        return score, None, []

    def _depth_windows(
        self, crop: _Crop, to_image: np.ndarray, window: _Window, mirror: bool
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """The HOG windows of a crop's own pixels (white on black) and, for the trained
        depth classifier, of its depth relative to theirs."""
        silhouette = (crop.mask * np.uint8(255)).astype(np.uint8)
        origin, stride = window.footprint[:2], window.stride
        relative = None
        if self.params.depth_classifier == "trained":
            image = relative_depth(crop.camera[2], crop.mask)
            relative = person_window(image, to_image, origin, stride, mirror, 255)
        return person_window(silhouette, to_image, origin, stride, mirror), relative

    def _crop(
        self,
        head: np.ndarray,
        height: float,
        cloud: OrganisedCloud,
        g_T_c: np.ndarray,
        footprint: tuple[int, int, int, int],
        stride: int,
    ) -> _Crop:
        """A strided crop of the window (x, y, z in the camera and in the ground frame),
        its valid pixels, and the candidate's own: near its axis (``head``, on the floor),
        above the floor, below its head (``height``)."""
        p = self.params
        u0, v0, u1, v1 = footprint
        if u1 > u0 and v1 > v0:
            crop_c = cloud.components(slice(v0, v1, stride), slice(u0, u1, stride))
            crop_g = _transform_xyz(g_T_c, *crop_c)
        else:
            crop_c = crop_g = tuple(np.full((0, 0), np.nan) for _ in range(3))
        gx, gy, gz = crop_g
        hx, hy = float(head[0]), float(head[1])
        valid = np.isfinite(gz)
        with np.errstate(invalid="ignore"):
            mask = (
                valid
                & (np.hypot(gx - hx, gy - hy) < float(p.person_radius))
                & (gz > float(p.ground_inlier_distance))
                & (gz < height + float(p.voxel_size))
            )
        return _Crop(crop_c, crop_g, valid, mask)

    def _histogram(
        self,
        crop: _Crop,
        color: np.ndarray | None,
        color_intrinsics: Intrinsics,
        cloud: OrganisedCloud,
        footprint: tuple[int, int, int, int],
        stride: int,
    ) -> list[float]:
        """The person's colour histogram (HSV), from the crop's person pixels."""
        if color is None or not np.any(crop.mask):
            return []
        u0, v0, u1, v1 = footprint
        if color_intrinsics is cloud.intrinsics:  # registered: the same pixels
            person_colors = color[v0:v1:stride, u0:u1:stride][crop.mask]
        else:
            uv, _ = project(np.stack([c[crop.mask] for c in crop.camera], axis=1), color_intrinsics)
            u = np.rint(uv[:, 0]).astype(np.int64)
            v = np.rint(uv[:, 1]).astype(np.int64)
            inside = (u >= 0) & (u < color.shape[1]) & (v >= 0) & (v < color.shape[0])
            person_colors = color[v[inside], u[inside]]
        p = self.params
        return hsv_histogram(
            person_colors, int(p.histogram_hue_bins), int(p.histogram_saturation_bins)
        )

    def _box(
        self, pixels: np.ndarray, person_px: float, shape: tuple[int, int]
    ) -> tuple[int, int, int, int]:
        """The person's image box (x, y, width, height), enlarged as OpenPTrack's."""
        rows, cols = shape
        box_h = person_px * float(self.params.box_enlarge_factor)
        box_w = box_h / 2.0
        bx0 = max(0, int(pixels[2][0] - box_w / 2.0))
        by0 = max(0, int(pixels[2][1] - box_h / 2.0))
        bx1 = min(cols, int(pixels[2][0] + box_w / 2.0))
        by1 = min(rows, int(pixels[2][1] + box_h / 2.0))
        return (bx0, by0, max(bx1 - bx0, 0), max(by1 - by0, 0))

    def _position(self, center_c: np.ndarray, g_T_c: np.ndarray) -> dict[str, Any]:
        """The detection's position (world, or ground frame) and its camera-frame point,
        pushed back by the centroid depth compensation."""
        compensation = float(self.params.centroid_depth_compensation)
        cx, cy, cz = (float(v) for v in center_c)
        camera_xyz = center_c * (1.0 + compensation / math.sqrt(cx * cx + cy * cy + cz * cz))
        pose = self.world_T_camera if self.world_T_camera is not None else g_T_c
        position = pose[:3, :3] @ camera_xyz + pose[:3, 3]
        return {
            "x": float(position[0]),
            "y": float(position[1]),
            "z": float(position[2]),
            "camera_xyz": (float(camera_xyz[0]), float(camera_xyz[1]), float(camera_xyz[2])),
        }
