"""The simulated venue as a whole: sensors, people, board, frames and ground truth.

:class:`Simulation` is deterministic for a seed: the people's motion, the
sensors' clock offsets and frame phases, the timestamp jitter and every
noise sample come from generators spawned from that seed in a fixed order,
so that two processes simulating the same scenario (one per sensor, say)
agree on where everyone is, and the same seed gives the same recording.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import open3d as o3d

from optrack.geometry import invert, make_pose, transform_points
from optrack.params import Param, Params, Schema, register
from optrack.recording.format import BoardTruth, GroundTruth, PersonTruth, SensorInfo
from optrack.sim.board import BOARD_PARAMS, PhysicalBoard
from optrack.sim.board_operator import Operator
from optrack.sim.board_plan import SensorView, plan_board_steps
from optrack.sim.body import BODY_PARAMS, MATERIALS_PER_PERSON, BodyModel, BodyShape, BodyState
from optrack.sim.crowd import CROWD_PARAMS, Crowd, CrowdState
from optrack.sim.materials import MaterialTable
from optrack.sim.mocap import add_performers, pose_people
from optrack.sim.models import MODELS, SensorModel
from optrack.sim.render import RENDER_PARAMS, DynamicGeometry, SensorRenderer, StaticScene
from optrack.sim.scenario import Scenario, ScenarioError, load_scenario
from optrack.sim.venue import Venue
from optrack.types import RGBDFrame, as_matrix4

__all__ = ["SIM_PARAMS", "SimSensor", "Simulation", "WorldState"]

SIM_PARAMS = register(
    Schema(
        "sim",
        [
            Param(
                "sensor_inset",
                0.25,
                0.05,
                2.0,
                0.05,
                "m",
                "Sensors placed around the room sit this far inside the walls.",
            ),
            Param(
                "visibility_stride",
                3,
                1,
                64,
                1,
                "",
                "Every n-th mesh vertex samples a body for its visible fraction.",
            ),
            Param(
                "visibility_epsilon",
                0.01,
                0.0001,
                0.2,
                0.001,
                "m",
                "A sample this close behind a hit still counts as seen.",
            ),
            Param("max_people", 100, 1, 1000, 1, "", "Most people a simulation accepts."),
            Param("max_sensors", 16, 1, 64, 1, "", "Most sensors a simulation accepts."),
            Param(
                "max_seconds",
                3600.0,
                1.0,
                86400.0,
                1.0,
                "s",
                "Longest simulation a command accepts.",
            ),
            Param("truth_decimals", 4, 1, 9, 1, "", "Decimals kept in ground-truth coordinates."),
        ],
        help="The simulated venue: sensor placement and ground truth.",
    )
)

JITTER_LIMIT = 0.25  # jitter is clipped to this fraction of a frame period (stamps stay ordered)


@dataclasses.dataclass
class SimSensor:
    """One simulated sensor: its model, true pose, clock and frame schedule."""

    index: int
    id: str
    model: SensorModel
    world_T_camera: np.ndarray
    clock_offset: float
    phase: float
    uri: str

    def frame_time(self, n: int) -> float:
        """True (world clock) capture time of frame n, seconds."""
        return self.phase + n / self.model.fps

    @property
    def info(self) -> SensorInfo:
        matrix = as_matrix4(self.world_T_camera)
        return SensorInfo(
            id=self.id,
            intrinsics=self.model.intrinsics,
            model=self.model.name,
            uri=self.uri,
            depth_scale=0.001,
            world_T_camera=matrix,  # type: ignore[arg-type]
            fps=self.model.fps,
            streams=list(self.model.streams),
        )


@dataclasses.dataclass
class WorldState:
    """Everything that moves, at one instant."""

    t: float
    crowd: CrowdState
    joints: np.ndarray  # (P, len(JOINTS), 3)
    vertices: np.ndarray  # (P, vertices_per_person, 3)
    board_pose: np.ndarray | None
    board_on_floor: bool
    geometry: DynamicGeometry
    body: BodyState | None = None  # the joint-angle state and every joint's global rotation
    shapes: list[BodyShape] = dataclasses.field(default_factory=list)  # each present person's


def _camera_pose(position: np.ndarray, forward: np.ndarray, roll: float = 0.0) -> np.ndarray:
    """``world_T_camera`` of a camera at ``position`` looking along ``forward`` (OpenCV axes)."""
    z = np.asarray(forward, dtype=np.float64)
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    if np.linalg.norm(x) < 1e-6:
        x = np.array([1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    rotation = np.stack([x, y, z], axis=1)
    if roll:
        c, s = math.cos(roll), math.sin(roll)
        rotation = rotation @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return make_pose(rotation, position)


class Simulation:
    """A scenario brought to life (see the module docstring).

    ``people``, ``sensors``, ``sensor_model`` and ``seconds`` override the
    scenario's own values; ``params`` maps stage names (``sim_crowd``,
    ``sim_kinect2``, ...) to their :class:`~optrack.params.Params`.
    """

    def __init__(
        self,
        scenario: Scenario | str,
        *,
        seed: int = 0,
        people: int | None = None,
        sensors: int | None = None,
        sensor_model: str | None = None,
        seconds: float | None = None,
        params: dict[str, Params] | None = None,
        clips: list[str] | None = None,
    ) -> None:
        self.scenario = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
        self.seed = int(seed)
        params = dict(params or {})
        self.params = params.get("sim") or SIM_PARAMS.create()
        self.render_params = params.get("sim_render") or RENDER_PARAMS.create()
        self._check_overrides(people, sensors, sensor_model, seconds)
        streams = np.random.SeedSequence(self.seed).spawn(4)
        crowd_rng, sensor_rng = np.random.default_rng(streams[0]), np.random.default_rng(streams[1])
        self._noise_seed = streams[2]
        self.venue = Venue(self.scenario.venue)
        self.static = StaticScene(self.venue)
        self.sensors = self._place_sensors(sensors, sensor_model, sensor_rng, params)
        self.body = BodyModel(
            params.get("sim_body") or BODY_PARAMS.create(),
            shape_seed=streams[3],
            varied=self.scenario.people.shapes == "varied",
        )
        self.crowd = Crowd(
            self.venue,
            crowd_rng,
            params.get("sim_crowd") or CROWD_PARAMS.create(),
            self.body.params,
        )
        self.seconds = float(seconds if seconds is not None else self.scenario.seconds)
        low, high = self.scenario.people_count_range()
        count = people if people is not None else int(crowd_rng.integers(low, high + 1))
        self.board: PhysicalBoard | None = None
        self.operator: Operator | None = None
        if self.scenario.board is not None:
            self._add_operator(params.get("sim_board") or BOARD_PARAMS.create(), seconds)
        clips = list(clips or self.scenario.people.clips)
        base = str(Path(self.scenario.source).parent) if self.scenario.source else None
        performers = add_performers(
            self.crowd, self.body, self.scenario.people, clips, count, self.seconds, base
        )
        self.crowd.populate(self.scenario.people, count - len(performers), self.seconds)
        self._renderers: dict[tuple, SensorRenderer] = {}
        self._noise: dict[int, np.random.Generator] = {}
        self._jitter: dict[int, np.random.Generator] = {}
        self._layout_key: tuple | None = None

    # ----------------------------------------------------------- set-up
    def _check_overrides(
        self, people: int | None, sensors: int | None, model: str | None, seconds: float | None
    ) -> None:
        p = self.params
        if people is not None and not 0 <= people <= p.max_people:
            raise ScenarioError(f"--people must be 0-{p.max_people}; got {people}.")
        if sensors is not None and not 1 <= sensors <= p.max_sensors:
            raise ScenarioError(f"--sensors must be 1-{p.max_sensors}; got {sensors}.")
        if model is not None and model not in MODELS:
            raise ScenarioError(
                f"--sensor-model must be one of {', '.join(MODELS)}; got '{model}'."
            )
        if seconds is not None and not (0 < seconds <= p.max_seconds and math.isfinite(seconds)):
            raise ScenarioError(
                f"--seconds must be above 0 and at most {p.max_seconds:g}; got {seconds}."
            )

    def _place_sensors(
        self,
        count: int | None,
        model_name: str | None,
        rng: np.random.Generator,
        params: dict[str, Params],
    ) -> list[SimSensor]:
        spec = self.scenario.sensors
        count = spec.count if count is None else count
        names, ids = spec.model_names(count, model_name), spec.sensor_ids(count, model_name)
        poses: list[np.ndarray] = []
        if spec.poses and count <= len(spec.poses):
            for pose in spec.poses[:count]:
                at = np.asarray(pose.at, dtype=np.float64)
                poses.append(
                    _camera_pose(at, np.asarray(pose.look_at) - at, math.radians(pose.roll_deg))
                )
        else:
            half = self.venue.half - float(self.params.sensor_inset)
            first = math.atan2(half[1], half[0])
            tilt = math.radians(spec.tilt_deg)
            for k in range(count):
                angle = first + 2 * math.pi * k / count
                direction = np.array([math.cos(angle), math.sin(angle)])
                scale = min(
                    half[0] / max(abs(direction[0]), 1e-9), half[1] / max(abs(direction[1]), 1e-9)
                )
                position = np.append(direction * scale, spec.height)
                yaw = angle + math.pi
                forward = np.array(
                    [
                        math.cos(tilt) * math.cos(yaw),
                        math.cos(tilt) * math.sin(yaw),
                        -math.sin(tilt),
                    ]
                )
                poses.append(_camera_pose(position, forward))
        sensors = []
        offsets = rng.uniform(-spec.clock_offset_max_s, spec.clock_offset_max_s, len(poses))
        phases = rng.random(len(poses))
        for k, pose in enumerate(poses):
            model_type = MODELS[names[k]]
            model = model_type(params.get(model_type.schema.stage))
            sensors.append(
                SimSensor(
                    index=k,
                    id=ids[k],
                    model=model,
                    world_T_camera=pose,
                    clock_offset=float(offsets[k]) if spec.clock_offset_max_s > 0 else 0.0,
                    phase=float(phases[k]) / model.fps,
                    uri=f"sim://{self.scenario.name}/{k}",
                )
            )
        return sensors

    def _add_operator(self, board_params: Params, seconds: float | None) -> None:
        spec = self.scenario.board
        assert spec is not None
        self.board = PhysicalBoard.from_spec(spec, board_params)
        views = [
            SensorView(s.world_T_camera, s.model.intrinsics, s.model.min_range, s.model.max_range)
            for s in self.sensors
        ]
        steps = plan_board_steps(
            views,
            self.venue,
            self.static.scene,
            spec,
            board_params,
            float(self.crowd.params.body_radius),
        )
        start = steps[0].operator_spot if steps else np.zeros(2)
        self.operator = Operator(steps, self.board, start)
        self.operator_index = self.crowd.add(self.operator)
        if seconds is None:
            self.seconds = max(self.seconds, self.operator.planned_seconds(start))

    # ------------------------------------------------------------ state
    def snapshot(self, t: float) -> WorldState:
        """The world at time ``t`` (seconds; calls must not go back in time)."""
        if t < self.crowd.t - 1e-9:
            raise ValueError(
                f"the simulation is at t={self.crowd.t:.3f} s and cannot go back to t={t:.3f} s."
            )
        self.crowd.advance(t)
        state = self.crowd.state(t)
        body, shapes = pose_people(self.body, self.crowd, state)
        vertices = self.body.vertices(body, shapes)
        board_pose = None
        on_floor = False
        if self.operator is not None:
            board_pose = self.operator.board_pose(self.crowd, self.operator_index).copy()
            on_floor = self.operator.on_floor
            if not on_floor:  # carried along with the operator since the last step
                board_pose[:2, 3] += self.crowd.vel[self.operator_index] * (t - self.crowd.t)
        geometry = self._geometry(state, vertices, board_pose)
        return WorldState(
            t, state, body.joints, vertices, board_pose, on_floor, geometry, body, shapes
        )

    def _geometry(
        self, state: CrowdState, vertices: np.ndarray, board_pose: np.ndarray | None
    ) -> DynamicGeometry:
        body = self.body
        count = len(state.ids)
        with_board = board_pose is not None and self.board is not None
        key = (tuple(state.index.tolist()), with_board)
        if key != self._layout_key:
            per_v = body.vertices_per_person
            tris = [body.template_triangles + k * per_v for k in range(count)]
            material = [body.template_material + k * MATERIALS_PER_PERSON for k in range(count)]
            owner = [np.full(len(body.template_triangles), k, dtype=np.int32) for k in range(count)]
            part = [body.template_part] * count
            texture = [body.template_texture] * count
            materials = [m for i in state.index for m in self.crowd.people[i].materials]
            if with_board:
                board = self.board
                tris.append(board.triangles + count * per_v)
                material.append(np.where(board.triangle_front, len(materials), len(materials) + 1))
                owner.append(np.full(len(board.triangles), count, dtype=np.int32))
                part.append(np.full(len(board.triangles), -1, dtype=np.int16))
                texture.append(np.zeros(len(board.triangles), dtype=np.float32))
                materials += board.materials
            self._layout = (
                np.concatenate(tris).astype(np.uint32) if tris else np.zeros((0, 3), np.uint32),
                np.concatenate(material).astype(np.int32) if material else np.zeros(0, np.int32),
                np.concatenate(owner) if owner else np.zeros(0, np.int32),
                np.concatenate(texture).astype(np.float32) if texture else np.zeros(0, np.float32),
                MaterialTable(materials),
                np.concatenate(part).astype(np.int16) if part else np.zeros(0, np.int16),
            )
            self._layout_key = key
        triangles, material, owner, texture, table, part = self._layout
        flat = vertices.reshape(-1, 3)
        boxes = list(np.stack([vertices.min(axis=1), vertices.max(axis=1)], axis=1))
        hulls = body.hulls(vertices) if count else []
        if with_board:
            board_vertices = transform_points(board_pose, self.board.vertices)
            flat = np.concatenate([flat, board_vertices])
            board_box = np.stack([board_vertices.min(axis=0), board_vertices.max(axis=0)])
            boxes.append(board_box)
            hulls.append(board_vertices[None])
        return DynamicGeometry(
            vertices=flat.astype(np.float32),
            triangles=triangles,
            triangle_material=material,
            triangle_owner=owner,
            triangle_part=part,
            triangle_texture=texture,
            materials=table,
            boxes=np.array(boxes).reshape(-1, 2, 3),
            hulls=[h.astype(np.float32) for h in hulls],
            board=self.board if with_board else None,
            world_T_board=board_pose if with_board else None,
        )

    # ---------------------------------------------------------- sensors
    def renderer(self, index: int, streams: tuple[str, ...] | None = None) -> SensorRenderer:
        """The renderer of sensor ``index`` (built once): all the model's streams, or only
        ``streams`` (e.g. ``("depth", "infrared")`` to skip colour)."""
        key = (index, streams)
        if key not in self._renderers:
            sensor = self.sensors[index]
            model = sensor.model
            wanted = model.streams if streams is None else streams
            self._renderers[key] = SensorRenderer(
                self.static,
                model.intrinsics,
                sensor.world_T_camera,
                self.scenario.venue.lighting,
                radiance=(model.needs_radiance and "color" in wanted) or model.depth_needs_radiance,
                infrared=model.needs_infrared and "infrared" in wanted,
                second_view=model.second_view,
                params=self.render_params,
            )
        return self._renderers[key]

    def _generator(
        self, store: dict[int, np.random.Generator], index: int, salt: int
    ) -> np.random.Generator:
        if index not in store:
            store[index] = np.random.default_rng([*self._noise_seed.generate_state(2), index, salt])
        return store[index]

    def stamp(self, index: int, n: int) -> float:
        """Timestamp of frame n of sensor ``index`` on the sensor's own clock: the true
        capture time plus the sensor's clock offset and jitter (never going back)."""
        sensor = self.sensors[index]
        rng = self._generator(self._jitter, index, 1)
        limit = JITTER_LIMIT / sensor.model.fps
        jitter = float(np.clip(rng.normal(0.0, sensor.model.jitter), -limit, limit))
        return sensor.frame_time(n) + sensor.clock_offset + jitter

    def frame(
        self,
        index: int,
        n: int,
        state: WorldState,
        *,
        noise: bool = True,
        stamp: float | None = None,
    ) -> RGBDFrame:
        """Frame n of sensor ``index``, rendered in ``state`` (the world at its capture time).
        Frames of one sensor must be asked for in order for the noise to be reproducible."""
        sensor = self.sensors[index]
        result = self.renderer(index).render(state.geometry)
        measured = sensor.model.measure(result, self._generator(self._noise, index, 0), noise=noise)
        return RGBDFrame(
            depth=measured.depth,
            intrinsics=sensor.model.intrinsics,
            sensor_id=sensor.id,
            timestamp=self.stamp(index, n) if stamp is None else stamp,
            depth_scale=0.001,
            color=measured.color,
            infrared=measured.infrared,
            confidence=measured.confidence,
            seq=n,
        )

    # ------------------------------------------------------ ground truth
    def visible_fractions(self, state: WorldState) -> np.ndarray:
        """(P, sensors) fraction of each person's surface samples that each sensor sees:
        inside its image and range, and hidden by nothing but the person's own body."""
        count = len(state.crowd.ids)
        out = np.zeros((count, len(self.sensors)))
        if count == 0:
            return out
        stride = int(self.params.visibility_stride)
        samples = state.vertices[:, ::stride]  # (P, S, 3)
        per = samples.shape[1]
        points = samples.reshape(-1, 3)
        owner = np.repeat(np.arange(count), per)
        eps = float(self.params.visibility_epsilon)
        for k, sensor in enumerate(self.sensors):
            model = sensor.model
            camera = transform_points(invert(sensor.world_T_camera), points)
            z = camera[:, 2]
            intr = model.intrinsics
            with np.errstate(divide="ignore", invalid="ignore"):
                u = intr.fx * camera[:, 0] / z + intr.cx
                v = intr.fy * camera[:, 1] / z + intr.cy
            seen = (z >= model.min_range) & (z <= model.max_range)
            seen &= (u >= -0.5) & (u < intr.width - 0.5) & (v >= -0.5) & (v < intr.height - 0.5)
            index = np.flatnonzero(seen)
            if len(index):
                origin = sensor.world_T_camera[:3, 3]
                delta = points[index] - origin
                length = np.linalg.norm(delta, axis=1)
                rays = o3d.core.Tensor(
                    np.concatenate([np.broadcast_to(origin, delta.shape), delta], 1).astype(
                        np.float32
                    )
                )
                limit = 1.0 - eps / length
                static_t = self.static.scene.cast_rays(rays, nthreads=self.renderer_threads)[
                    "t_hit"
                ].numpy()
                hit = state.geometry.scene.cast_rays(rays, nthreads=self.renderer_threads)
                dynamic_t = hit["t_hit"].numpy()
                prim = hit["primitive_ids"].numpy()
                valid_prim = np.isfinite(dynamic_t)
                hit_owner = np.full(len(index), -1)
                hit_owner[valid_prim] = state.geometry.triangle_owner[prim[valid_prim]]
                clear = (static_t >= limit) & ((dynamic_t >= limit) | (hit_owner == owner[index]))
                seen[index] = clear
            out[:, k] = seen.reshape(count, per).mean(axis=1)
        return out

    @property
    def renderer_threads(self) -> int:
        return int(self.render_params.threads)

    def truth(self, state: WorldState, visibility: bool = True) -> GroundTruth:
        """Ground truth at the state's instant (world clock)."""
        decimals = int(self.params.truth_decimals)
        fractions = self.visible_fractions(state) if visibility else None
        people = []
        tops = state.body.head_tops(state.shapes)
        for k, person_id in enumerate(state.crowd.ids):
            joints, angles = state.body.truth(k, decimals)
            people.append(
                PersonTruth(
                    id=int(person_id),
                    x=joints["pelvis"][0],
                    y=joints["pelvis"][1],
                    height=round(float(tops[k]), decimals),
                    visible=(
                        {s.id: round(float(fractions[k, j]), 3) for j, s in enumerate(self.sensors)}
                        if fractions is not None
                        else {}
                    ),
                    joints=joints,
                    angles=angles,
                )
            )
        boards = []
        if state.board_pose is not None and self.board is not None:
            matrix = as_matrix4(state.board_pose)
            boards.append(
                BoardTruth(
                    world_T_board=matrix,  # type: ignore[arg-type]
                    cols=self.board.pattern.cols,
                    rows=self.board.pattern.rows,
                    square=self.board.pattern.square,
                    on_floor=state.board_on_floor,
                )
            )
        return GroundTruth(t=round(float(state.t), 6), people=people, boards=boards)

    # ---------------------------------------------------------- schedule
    def frame_count(self, index: int, seconds: float | None = None) -> int:
        """How many frames sensor ``index`` captures in the run (true times < seconds)."""
        sensor = self.sensors[index]
        seconds = self.seconds if seconds is None else seconds
        return max(0, int(math.ceil((seconds - sensor.phase) * sensor.model.fps - 1e-9)))
