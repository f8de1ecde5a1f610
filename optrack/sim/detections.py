"""Detection streams with known answers: people on known paths seen by ideal-ish sensors.

These exercise the tracker without rendering or detection: each sensor
"detects" the people in its field of view and range, with position noise
that grows with distance, a per-sensor calibration offset, misses (more when
partly hidden behind someone or a pillar), false alarms, HOG-like
confidences and a hue x saturation colour histogram per person. The result is
the time-ordered :class:`~optrack.types.DetectionBatch` stream every sensor
would send, and the ground truth at a fixed rate.

Used by the tracker's tests and by ``optrack bench tracking``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from optrack.tracking.motion import DEFAULT_VOXEL_SIZE
from optrack.types import Detection, DetectionBatch

__all__ = [
    "Path",
    "ScenePerson",
    "Scene",
    "SceneTruth",
    "SyntheticSensor",
    "crowd_scene",
    "person_histogram",
    "render",
]

HUE_BINS, SATURATION_BINS = 16, 4  # the detector's default histogram


class Path:
    """Piecewise-linear floor path: position at times ``t`` (s) is ``xy`` (m); absent outside."""

    def __init__(self, t: Sequence[float], xy: Sequence[Sequence[float]]) -> None:
        self.t = np.asarray(t, dtype=np.float64)
        self.xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        if len(self.t) != len(self.xy) or len(self.t) < 2 or np.any(np.diff(self.t) < 0):
            raise ValueError("a path needs at least two points with times in ascending order.")

    def at(self, time: float) -> tuple[float, float] | None:
        if time < self.t[0] or time > self.t[-1]:
            return None
        k = int(np.searchsorted(self.t, time, side="right")) - 1
        k = min(max(k, 0), len(self.t) - 2)
        span = self.t[k + 1] - self.t[k]
        w = 0.0 if span <= 0 else (time - self.t[k]) / span
        p = self.xy[k] + w * (self.xy[k + 1] - self.xy[k])
        return float(p[0]), float(p[1])


@dataclasses.dataclass(frozen=True)
class ScenePerson:
    id: int
    path: Path
    height: float = 1.75
    histogram: tuple[float, ...] = ()


@dataclasses.dataclass(frozen=True)
class SyntheticSensor:
    """A sensor on the floor plan at (x, y) looking along ``yaw`` (rad)."""

    id: str
    x: float
    y: float
    yaw: float
    fov_deg: float = 70.0
    min_range: float = 0.5
    max_range: float = 6.0
    rate: float = 30.0
    phase: float = 0.0
    offset: tuple[float, float] = (0.0, 0.0)  # calibration error, m


@dataclasses.dataclass(frozen=True)
class Scene:
    people: tuple[ScenePerson, ...]
    sensors: tuple[SyntheticSensor, ...]
    seconds: float
    pillars: tuple[tuple[float, float, float], ...] = ()  # (x, y, radius)
    body_radius: float = 0.2
    noise_std: float = 0.04  # m, at any distance
    depth_error: float = 0.0015  # 1/m: extra std k * d^2 along the ray
    miss_probability: float = 0.05
    occluded_miss_probability: float = 0.5
    false_alarms_per_frame: float = 0.05
    confidence_mean: float = 0.4  # like the detector's HOG margins on simulated people
    confidence_std: float = 1.1
    false_alarm_confidence_mean: float = -2.2  # the detector's false alarms: about -2.7
    histogram_noise: float = 0.15
    occluder_colour_share: float = 0.3  # of a partly hidden person's histogram
    truth_rate: float = 30.0


@dataclasses.dataclass
class SceneTruth:
    """Ground truth at ``truth_rate``: per instant, people present, and whether any sensor sees them."""

    times: np.ndarray  # (T,)
    ids: list[np.ndarray]  # per instant, (G,)
    xy: list[np.ndarray]  # per instant, (G, 2)
    visible: list[np.ndarray]  # per instant, (G,) bool


def person_histogram(
    hues: Sequence[float], saturations: Sequence[float], weights: Sequence[float]
) -> tuple[float, ...]:
    """A normalised hue x saturation histogram of clothes of the given colours (hue 0..1,
    saturation 0..1), smeared over neighbouring bins."""
    h = np.zeros((HUE_BINS, SATURATION_BINS))
    for hue, sat, w in zip(hues, saturations, weights, strict=True):
        hb = hue * HUE_BINS
        sb = min(sat * SATURATION_BINS, SATURATION_BINS - 1e-9)
        for dh in (-1, 0, 1):
            for ds in (-1, 0, 1):
                j = int(math.floor(sb)) + ds
                if not 0 <= j < SATURATION_BINS:
                    continue
                i = (int(math.floor(hb)) + dh) % HUE_BINS
                h[i, j] += w * (0.6 if dh == 0 and ds == 0 else 0.05)
    h /= h.sum()
    return tuple(float(v) for v in h.ravel())


def _random_histogram(rng: np.random.Generator) -> tuple[float, ...]:
    hues = rng.uniform(0, 1, size=2)
    sats = rng.uniform(0.1, 1.0, size=2)
    w = rng.uniform(0.3, 0.7)
    return person_histogram(hues, sats, (w, 1 - w))


def _ray_blocked(
    sx: float, sy: float, px: float, py: float, cx: float, cy: float, radius: float
) -> float:
    """How far (m) the ray sensor->person passes inside a disc before the person; <0 when clear."""
    dx, dy = px - sx, py - sy
    length2 = dx * dx + dy * dy
    u = ((cx - sx) * dx + (cy - sy) * dy) / length2
    if u <= 0.0 or u >= 1.0:
        return -1.0
    qx, qy = sx + u * dx, sy + u * dy
    return radius - math.hypot(cx - qx, cy - qy)


def _blocker(
    scene: Scene,
    sensor: SyntheticSensor,
    person: ScenePerson,
    xy: tuple[float, float],
    present: list[tuple[ScenePerson, tuple[float, float]]],
) -> tuple[float, tuple[float, ...]]:
    """How far the line of sight from ``sensor`` to ``person`` (at ``xy``) is blocked
    (the deepest overlap of a body or pillar, m; negative: clear) and the colours of the
    person blocking most (empty for a pillar)."""
    px, py = xy
    blocked = -1.0
    blocker_hist: tuple[float, ...] = ()
    for q, (qx, qy) in present:
        if q is person:
            continue
        b = _ray_blocked(sensor.x, sensor.y, px, py, qx, qy, 2 * scene.body_radius)
        if b > blocked:
            blocked, blocker_hist = b, q.histogram
    for cx, cy, r in scene.pillars:
        b = _ray_blocked(sensor.x, sensor.y, px, py, cx, cy, r + scene.body_radius)
        if b > blocked:
            blocked, blocker_hist = b, ()
    return blocked, blocker_hist


def _detection(
    scene: Scene,
    sensor: SyntheticSensor,
    person: ScenePerson,
    xy: tuple[float, float],
    present: list[tuple[ScenePerson, tuple[float, float]]],
    rng: np.random.Generator,
) -> Detection | None:
    """The sensor's detection of one person, or None (out of range or view, hidden
    behind someone or a pillar, or missed)."""
    px, py = xy
    dx, dy = px - sensor.x, py - sensor.y
    d = math.hypot(dx, dy)
    if not sensor.min_range <= d <= sensor.max_range:
        return None
    cos_half = math.cos(math.radians(sensor.fov_deg) / 2)
    if (dx * math.cos(sensor.yaw) + dy * math.sin(sensor.yaw)) / d < cos_half:
        return None
    blocked, blocker_hist = _blocker(scene, sensor, person, xy, present)
    partly = blocked > 0.0
    if blocked > scene.body_radius:  # fully hidden
        return None
    miss = scene.occluded_miss_probability if partly else scene.miss_probability
    if rng.random() < miss:
        return None
    along = rng.normal(0.0, scene.depth_error * d * d)
    ex, ey = rng.normal(0.0, scene.noise_std, size=2)
    hist = np.asarray(person.histogram, dtype=np.float64)
    if hist.size:
        hist = hist * rng.lognormal(0.0, scene.histogram_noise, size=hist.size)
        if partly and blocker_hist:  # the occluder's colours leak in
            share = scene.occluder_colour_share
            hist = (1 - share) * hist / hist.sum() + share * np.asarray(blocker_hist)
        hist = hist / hist.sum()
    return Detection(
        x=px + ex + along * dx / d + sensor.offset[0],
        y=py + ey + along * dy / d + sensor.offset[1],
        z=person.height / 2,
        height=person.height + float(rng.normal(0.0, 0.03)),
        confidence=float(rng.normal(scene.confidence_mean, scene.confidence_std)),
        camera_xyz=(0.0, 0.0, d),
        occluded=partly,
        histogram=[float(v) for v in hist],
    )


def _false_alarms(
    scene: Scene, sensor: SyntheticSensor, rng: np.random.Generator
) -> list[Detection]:
    """Detections of nobody, anywhere in the sensor's view."""
    alarms = []
    for _ in range(rng.poisson(scene.false_alarms_per_frame)):
        d = rng.uniform(sensor.min_range, sensor.max_range)
        a = sensor.yaw + rng.uniform(-1, 1) * math.radians(sensor.fov_deg) / 2
        alarms.append(
            Detection(
                x=sensor.x + d * math.cos(a),
                y=sensor.y + d * math.sin(a),
                z=0.8,
                height=float(rng.uniform(1.3, 2.0)),
                confidence=float(rng.normal(scene.false_alarm_confidence_mean, 0.5)),
                camera_xyz=(0.0, 0.0, d),
                histogram=list(_random_histogram(rng)),
            )
        )
    return alarms


def render(
    scene: Scene, seed: int = 0, arrival_jitter: float = 0.0
) -> tuple[list[DetectionBatch], SceneTruth]:
    """Every sensor's batches (in arrival order) and the ground truth.

    With ``arrival_jitter`` > 0 each batch arrives up to that many seconds
    after its stamp (uniform), so batches of different sensors come out of
    order, as over a network.
    """
    rng = np.random.default_rng(seed)
    people = list(scene.people)
    batches: list[tuple[float, DetectionBatch]] = []
    for sensor in scene.sensors:
        period = 1.0 / sensor.rate
        n_frames = int(math.floor((scene.seconds - sensor.phase) / period)) + 1
        for k in range(n_frames):
            t = sensor.phase + k * period
            present = [(p, p.path.at(t)) for p in people]
            present = [(p, xy) for p, xy in present if xy is not None]
            detections = [
                found
                for p, xy in present
                if (found := _detection(scene, sensor, p, xy, present, rng)) is not None
            ]
            detections += _false_alarms(scene, sensor, rng)
            arrival = t + (rng.uniform(0.0, arrival_jitter) if arrival_jitter > 0 else 0.0)
            batches.append(
                (
                    arrival,
                    DetectionBatch(
                        sensor_id=sensor.id,
                        stamp=t,
                        seq=k,
                        detections=detections,
                        voxel_size=DEFAULT_VOXEL_SIZE,
                    ),
                )
            )
    batches.sort(key=lambda item: (item[0], item[1].stamp, item[1].sensor_id))
    return [b for _, b in batches], _truth(scene)


def _truth(scene: Scene) -> SceneTruth:
    times = np.arange(0.0, scene.seconds + 1e-9, 1.0 / scene.truth_rate)
    ids, xys, visible = [], [], []
    for t in times:
        present = [(p, p.path.at(float(t))) for p in scene.people]
        present = [(p, xy) for p, xy in present if xy is not None]
        ids.append(np.array([p.id for p, _ in present], dtype=np.int64))
        xys.append(np.array([xy for _, xy in present], dtype=np.float64).reshape(-1, 2))
        seen = []
        for p, (px, py) in present:
            seen.append(any(_sees(scene, s, p, px, py, present) for s in scene.sensors))
        visible.append(np.array(seen, dtype=bool))
    return SceneTruth(times, ids, xys, visible)


def _sees(
    scene: Scene,
    sensor: SyntheticSensor,
    person: ScenePerson,
    px: float,
    py: float,
    present: list[tuple[ScenePerson, tuple[float, float]]],
) -> bool:
    dx, dy = px - sensor.x, py - sensor.y
    d = math.hypot(dx, dy)
    if not sensor.min_range <= d <= sensor.max_range:
        return False
    if (dx * math.cos(sensor.yaw) + dy * math.sin(sensor.yaw)) / d < math.cos(
        math.radians(sensor.fov_deg) / 2
    ):
        return False
    for q, (qx, qy) in present:
        if (
            q is not person
            and _ray_blocked(sensor.x, sensor.y, px, py, qx, qy, 2 * scene.body_radius)
            > scene.body_radius
        ):
            return False
    for cx, cy, r in scene.pillars:
        if (
            _ray_blocked(sensor.x, sensor.y, px, py, cx, cy, r + scene.body_radius)
            > scene.body_radius
        ):
            return False
    return True


def _walk_together(
    rng: np.random.Generator,
    people: int,
    room: tuple[float, float],
    seconds: float,
    speed: tuple[float, float],
    personal_space: float = 0.6,
    step: float = 0.1,
) -> list[Path]:
    """Walkers going from random point to random point (pausing now and then), steering
    round each other so that nobody comes closer than ``personal_space`` to anyone."""
    margin = 0.4
    lo = np.array([margin, margin])
    hi = np.array([room[0] - margin, room[1] - margin])

    def spot() -> np.ndarray:
        return rng.uniform(lo, hi)

    p = np.zeros((people, 2))
    for i in range(people):  # start apart
        for _ in range(1000):
            p[i] = spot()
            if i == 0 or np.min(np.linalg.norm(p[:i] - p[i], axis=1)) > 2 * personal_space:
                break
    goal = np.array([spot() for _ in range(people)])
    pace = rng.uniform(*speed, size=people)
    pause = np.zeros(people)
    steps = int(math.ceil(seconds / step)) + 1
    track = np.zeros((steps, people, 2))
    for k in range(steps):
        track[k] = p
        for i in range(people):
            if pause[i] > 0:
                pause[i] -= step
                continue
            to_goal = goal[i] - p[i]
            d = np.linalg.norm(to_goal)
            if d < 0.2:
                goal[i] = spot()
                if rng.random() < 0.3:
                    pause[i] = rng.uniform(0.5, 3.0)
                continue
            v = pace[i] * to_goal / d
            others = np.delete(p, i, axis=0)
            away = p[i] - others
            dist = np.linalg.norm(away, axis=1)
            near = dist < 2.5 * personal_space
            if near.any():  # social-force-like push from the people close by
                push = (away[near] / dist[near, None] ** 2).sum(axis=0) * personal_space
                v = v + pace[i] * push
                norm = np.linalg.norm(v)
                if norm > pace[i]:
                    v *= pace[i] / norm
            proposal = np.clip(p[i] + v * step, lo, hi)
            if others.size and np.min(np.linalg.norm(others - proposal, axis=1)) < personal_space:
                sidestep = np.array([-v[1], v[0]]) * step
                proposal = np.clip(p[i] + sidestep, lo, hi)
                if np.min(np.linalg.norm(others - proposal, axis=1)) < personal_space:
                    continue  # wait for the way to clear
            p[i] = proposal
    times = np.arange(steps) * step
    return [Path(times, track[:, i]) for i in range(people)]


def crowd_scene(
    people: int,
    sensors: int,
    seconds: float,
    seed: int = 0,
    room: tuple[float, float] | None = None,
    rate: float = 30.0,
    calibration_error: float = 0.05,
    **scene_options: float,
) -> Scene:
    """People walking between random points of a room watched by sensors around its edge.

    Walkers keep 0.6 m apart. Room size defaults to about 3 m^2 per person (at least 6 x 5 m); sensors
    stand evenly on an ellipse around the room, looking at its centre, with
    range enough to see its far side, random phases and calibration offsets.
    """
    rng = np.random.default_rng(seed)
    if room is None:
        side = max(6.0, math.sqrt(3.0 * people))
        room = (side, max(5.0, side * 5 / 6))
    paths = _walk_together(rng, people, room, seconds, (0.8, 1.4))
    walkers = tuple(
        ScenePerson(
            id=i + 1,
            path=path,
            height=float(rng.uniform(1.55, 1.95)),
            histogram=_random_histogram(rng),
        )
        for i, path in enumerate(paths)
    )
    cx, cy = room[0] / 2, room[1] / 2
    reach = math.hypot(room[0], room[1]) + 0.5
    cams = []
    for k in range(sensors):
        a = 2 * math.pi * k / sensors + math.pi / 4
        sx, sy = cx + 0.55 * room[0] * math.cos(a), cy + 0.55 * room[1] * math.sin(a)
        offset = rng.normal(0.0, calibration_error, size=2) if calibration_error > 0 else (0, 0)
        cams.append(
            SyntheticSensor(
                id=f"s{k + 1}",
                x=sx,
                y=sy,
                yaw=math.atan2(cy - sy, cx - sx),
                max_range=reach,
                rate=rate,
                phase=float(rng.uniform(0, 1.0 / rate)),
                offset=(float(offset[0]), float(offset[1])),
            )
        )
    return Scene(people=walkers, sensors=tuple(cams), seconds=seconds, **scene_options)
