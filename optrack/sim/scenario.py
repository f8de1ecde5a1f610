"""Scenario files: a venue, its sensors, its people and (optionally) a checkerboard.

A scenario is a YAML file; the built-in ones live in ``optrack/resources/scenarios``
and are named by their file stem (``crowd``, ``mixed``, ...). A file that
cannot be read, is not YAML, or holds a wrong field gives a
:class:`ScenarioError` whose message is one sentence naming the file, the
field and what to do. Coordinates are world metres: origin at the centre of
the room on the floor, x along the room's length, y along its width, z up.

::

    description: two people walking behind furniture
    seconds: 20
    venue:
      size: [8.0, 6.0]            # length (x) and width (y), metres
      wall_height: 3.0
      doors: [{wall: west, at: 0.0, width: 1.0}]
      obstacles:
        - {kind: pillar, at: [1.5, 1.0], radius: 0.2}
        - {kind: table, at: [0, -1], size: [1.4, 0.8], height: 0.75, yaw_deg: 10}
        - {kind: box, at: [2, 2], size: [0.6, 0.4, 0.5]}
        - {kind: partition, from: [-1, 0.5], to: [0.5, 0.5], height: 1.8}
      lighting: {level: 1.0}
    sensors: {count: 3, model: kinect2, height: 2.6, tilt_deg: 30}
    # or mixed models, one per sensor: {count: 4, models: [kinect2, kinect1, stereo, sr4500]}
    people:
      count: [4, 6]               # a number, or [min, max] drawn per seed
      standing: 1
      groups: [2]
      crossing: 1
      enter_leave: 1
      routes: [[[-3, -2], [3, -2], [3, 2]]]
    board: {cols: 6, rows: 5, square: 0.12, floor_placements: 3}
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Literal

import msgspec
import yaml

from optrack.errors import UserError
from optrack.resources import scenario_dir

__all__ = [
    "SCENARIO_DIR",
    "BoardSpec",
    "Box",
    "Door",
    "Lighting",
    "Partition",
    "PeopleSpec",
    "Pillar",
    "Scenario",
    "ScenarioError",
    "SensorPose",
    "SensorsSpec",
    "Table",
    "VenueSpec",
    "builtin_scenarios",
    "load_scenario",
]

SCENARIO_DIR = scenario_dir()  # inside the package (optrack/resources/scenarios)
SENSOR_MODEL_NAMES = ("kinect2", "kinect1", "sr4500", "stereo")


class ScenarioError(UserError):
    """A scenario file or scenario option that cannot be used."""


Vec2 = tuple[float, float]
Vec3 = tuple[float, float, float]
Color = tuple[float, float, float]


class _Spec(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    pass


class Pillar(_Spec, tag="pillar", tag_field="kind"):
    """A round pillar from floor to ceiling."""

    at: Vec2
    radius: float = 0.2
    color: Color = (0.78, 0.77, 0.74)
    texture: float = 0.25


class Table(_Spec, tag="table", tag_field="kind"):
    """A table: a top slab on four legs (people are seen between the legs)."""

    at: Vec2
    size: Vec2 = (1.2, 0.8)
    height: float = 0.75
    yaw_deg: float = 0.0
    color: Color = (0.55, 0.38, 0.24)
    texture: float = 0.25


class Box(_Spec, tag="box", tag_field="kind"):
    """A closed box standing on the floor (crates, cabinets)."""

    at: Vec2
    size: Vec3 = (0.6, 0.4, 0.5)
    yaw_deg: float = 0.0
    color: Color = (0.62, 0.52, 0.36)
    texture: float = 0.25


class Partition(_Spec, tag="partition", tag_field="kind"):
    """A thin standing panel from one floor point to another."""

    start: Vec2 = msgspec.field(name="from")
    to: Vec2
    height: float = 1.8
    thickness: float = 0.06
    color: Color = (0.35, 0.45, 0.6)
    texture: float = 0.25


Obstacle = Pillar | Table | Box | Partition


class Door(_Spec):
    """An opening in a wall, where people enter and leave. ``at`` is the offset of its
    centre from the middle of the wall, metres."""

    wall: Literal["north", "south", "east", "west"]
    at: float = 0.0
    width: float = 1.0


class Lighting(_Spec):
    """Room lighting: ``level`` 1 is a lit office, 0.02 is near dark. One directional
    light (azimuth, elevation) plus an ``ambient`` share."""

    level: float = 1.0
    ambient: float = 0.35
    azimuth_deg: float = 30.0
    elevation_deg: float = 60.0


class VenueSpec(_Spec):
    size: Vec2 = (8.0, 6.0)
    wall_height: float = 3.0
    ceiling: bool = True
    doors: list[Door] = []
    obstacles: list[Obstacle] = []
    lighting: Lighting = msgspec.field(default_factory=Lighting)
    floor_color: Color = (0.52, 0.5, 0.47)
    wall_color: Color = (0.86, 0.85, 0.82)
    floor_texture: float = 0.15
    wall_texture: float = 0.0
    texture_cell: float = 0.02


class SensorPose(_Spec):
    """One sensor placed by hand: its optical centre and a point it looks at."""

    at: Vec3
    look_at: Vec3
    roll_deg: float = 0.0


ModelName = Literal["kinect2", "kinect1", "sr4500", "stereo"]


class SensorsSpec(_Spec):
    """Sensors placed around the room's perimeter (``count``, ``height``, ``tilt_deg``)
    unless ``poses`` places them by hand. Every sensor is a ``model`` unless ``models``
    gives one per sensor, in order (repeated when shorter than ``count``)."""

    count: int = 3
    model: ModelName = "kinect2"
    models: list[ModelName] = []
    height: float = 2.6
    tilt_deg: float = 30.0
    poses: list[SensorPose] = []
    clock_offset_max_s: float = 0.0

    def model_names(self, count: int | None = None, model: str | None = None) -> list[str]:
        """Each sensor's model, in order: ``model`` for every one when given, else
        ``models`` repeated, else ``model``."""
        count = self.count if count is None else count
        names = [model] if model else (list(self.models) or [self.model])
        return [names[k % len(names)] for k in range(count)]

    def sensor_ids(self, count: int | None = None, model: str | None = None) -> list[str]:
        """Each sensor's id: its model and its index (``kinect2_0``, ...)."""
        return [f"{name}_{k}" for k, name in enumerate(self.model_names(count, model))]


class PeopleSpec(_Spec):
    """Who walks in the venue. Routes go to the first people; then standing people,
    groups, crossing pairs and people who enter and leave; the rest wander. With
    ``clips`` (BVH files, relative to the scenario file, or procedural motions: walk,
    wave, crouch, turn), everyone performs them instead, person k clip k modulo their
    number. ``shapes: varied`` gives each person a shape of their own (limb lengths,
    girths, tapering limbs); ``standard`` is Winter's proportions for all."""

    count: int | tuple[int, int] = 4
    children: float = 0.0
    area: tuple[float, float, float, float] | None = None
    standing: int = 0
    groups: list[int] = []
    crossing: int = 0
    enter_leave: int = 0
    routes: list[list[Vec2]] = []
    clips: list[str] = []
    shapes: Literal["standard", "varied"] = "standard"


class BoardSpec(_Spec):
    """The checkerboard an operator carries: inner corners ``cols`` x ``rows``."""

    cols: int = 6
    rows: int = 5
    square: float = 0.12
    floor_placements: int = 3
    # More floor placements, until every sensor that can see the floor has seen
    # the board on it at this many (0: floor_placements only); the simulated operator's.
    floor_per_sensor: int = 0
    # (added) Intrinsics: the operator shows the board to this sensor alone (its index),
    # at ``intrinsics_placements`` places across its image, each turned another way,
    # instead of the network procedure; -1: the network procedure.
    intrinsics_sensor: int = -1
    intrinsics_placements: int = 9
    # The network procedure's placements the operator makes: all (facing each
    # sensor, then pairs, then the floor), pairs (pairs, then the floor) or floor (the
    # floor only); the simulated operator asks for what the wizard's page needs.
    steps: Literal["all", "pairs", "floor"] = "all"


class Scenario(_Spec):
    name: str = ""
    description: str = ""
    seconds: float = 20.0
    venue: VenueSpec = msgspec.field(default_factory=VenueSpec)
    sensors: SensorsSpec = msgspec.field(default_factory=SensorsSpec)
    people: PeopleSpec = msgspec.field(default_factory=PeopleSpec)
    board: BoardSpec | None = None
    source: str = ""

    def people_count_range(self) -> tuple[int, int]:
        count = self.people.count
        return (count, count) if isinstance(count, int) else (int(count[0]), int(count[1]))


# ------------------------------------------------------------------ loading


def builtin_scenarios() -> list[str]:
    """Names of the scenarios shipped in optrack/resources/scenarios."""
    if not SCENARIO_DIR.is_dir():
        return []
    return sorted(p.stem for p in SCENARIO_DIR.glob("*.yaml"))


def _resolve(name_or_path: str | os.PathLike[str]) -> Path:
    text = os.fspath(name_or_path)
    path = Path(text)
    if path.suffix.lower() in (".yaml", ".yml") or os.sep in text or path.exists():
        return path
    candidate = SCENARIO_DIR / f"{text}.yaml"
    if candidate.is_file():
        return candidate
    known = ", ".join(builtin_scenarios()) or "none found"
    raise ScenarioError(
        f"unknown scenario '{text}' (built in: {known}); give one of those names or a YAML file."
    )


def _field_error(path: Path, error: msgspec.ValidationError) -> ScenarioError:
    message = str(error)
    where = ""
    if " - at `$" in message:
        message, _, location = message.partition(" - at `$")
        where = location.rstrip("`").lstrip(".")
    message = message.replace("`", "'").replace("Object contains unknown", "unknown").rstrip(".")
    if message:
        message = message[0].lower() + message[1:]
    field = f" field '{where}'" if where else ""
    return ScenarioError(f"scenario file {path}{field}: {message}; fix it and try again.")


def load_scenario(name_or_path: str | os.PathLike[str]) -> Scenario:
    """A built-in scenario by name, or a scenario YAML file, checked."""
    path = _resolve(name_or_path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ScenarioError(
            f"scenario file {path} does not exist; check the path or use a built-in scenario "
            f"({', '.join(builtin_scenarios())})."
        ) from None
    except (OSError, UnicodeDecodeError) as error:
        reason = getattr(error, "strerror", None) or "not UTF-8 text"
        raise ScenarioError(f"scenario file {path} cannot be read ({reason}).") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        raise ScenarioError(f"scenario file {path} is not valid YAML{where}; fix it.") from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ScenarioError(
            f"scenario file {path} must be a mapping (description, venue, sensors, people, ...)."
        )
    try:
        scenario = msgspec.convert(data, Scenario)
    except msgspec.ValidationError as error:
        raise _field_error(path, error) from None
    scenario = msgspec.structs.replace(scenario, name=scenario.name or path.stem, source=str(path))
    check_scenario(scenario)
    return scenario


# --------------------------------------------------------------- semantics


def _fail(scenario: Scenario, what: str) -> ScenarioError:
    origin = f"scenario file {scenario.source}" if scenario.source else f"scenario {scenario.name}"
    return ScenarioError(f"{origin}: {what}.")


def _inside(scenario: Scenario, point: Vec2, margin: float = 0.0) -> bool:
    half_x, half_y = scenario.venue.size[0] / 2 - margin, scenario.venue.size[1] / 2 - margin
    return abs(point[0]) <= half_x and abs(point[1]) <= half_y


def _finite(values: object) -> bool:
    if isinstance(values, int | float):
        return math.isfinite(values)
    if isinstance(values, tuple | list):
        return all(_finite(v) for v in values)
    if isinstance(values, dict):
        return all(_finite(v) for v in values.values())
    return True


def check_scenario(scenario: Scenario) -> None:
    """Raise a :class:`ScenarioError` naming the first field that makes no sense."""
    if not _finite(msgspec.to_builtins(scenario)):
        raise _fail(scenario, "every number must be finite (no .inf or .nan)")
    _check_venue(scenario)
    _check_obstacles(scenario)
    _check_sensors(scenario)
    _check_people(scenario)
    if not 0.0 < scenario.seconds <= 3600.0:
        raise _fail(scenario, f"seconds must be above 0 and at most 3600; got {scenario.seconds}")
    _check_board(scenario)


def _check_venue(scenario: Scenario) -> None:
    venue = scenario.venue
    length, width = venue.size
    if not (1.0 <= length <= 100.0 and 1.0 <= width <= 100.0):
        raise _fail(scenario, f"venue.size must be between 1 and 100 m per side; got {venue.size}")
    if not 2.0 <= venue.wall_height <= 20.0:
        raise _fail(scenario, f"venue.wall_height must be 2-20 m; got {venue.wall_height}")
    if not 0.0 <= venue.lighting.level <= 10.0:
        raise _fail(scenario, f"venue.lighting.level must be 0-10; got {venue.lighting.level}")
    if not 0.0 <= venue.lighting.ambient <= 1.0:
        raise _fail(scenario, f"venue.lighting.ambient must be 0-1; got {venue.lighting.ambient}")
    for name, color in (("floor_color", venue.floor_color), ("wall_color", venue.wall_color)):
        if not all(0.0 <= c <= 1.0 for c in color):
            raise _fail(scenario, f"venue.{name} must be three numbers 0-1; got {color}")
    for i, door in enumerate(venue.doors):
        span = length if door.wall in ("north", "south") else width
        if door.width <= 0.3 or abs(door.at) + door.width / 2 > span / 2:
            raise _fail(scenario, f"venue.doors[{i}] must be wider than 0.3 m and fit its wall")


def _check_obstacles(scenario: Scenario) -> None:
    venue = scenario.venue
    length, width = venue.size
    for i, obstacle in enumerate(venue.obstacles):
        where = f"venue.obstacles[{i}] ({type(obstacle).__name__.lower()})"
        points = [obstacle.start, obstacle.to] if isinstance(obstacle, Partition) else [obstacle.at]
        if not all(_inside(scenario, p) for p in points):
            raise _fail(scenario, f"{where} is outside the {length} x {width} m room")
        # (horizontal sizes, heights) of the obstacle
        if isinstance(obstacle, Pillar):
            flat, tall = [2 * obstacle.radius], []
        elif isinstance(obstacle, Table):
            flat, tall = list(obstacle.size), [obstacle.height]
        elif isinstance(obstacle, Box):
            flat, tall = list(obstacle.size[:2]), [obstacle.size[2]]
        else:
            flat, tall = [obstacle.thickness], [obstacle.height]
            if math.dist(obstacle.start, obstacle.to) < 0.1:
                raise _fail(scenario, f"{where} must be at least 0.1 m long")
        if not all(0.0 < s <= max(length, width) for s in flat):
            raise _fail(scenario, f"{where} sizes must be positive and fit in the room")
        if not all(0.0 < s <= venue.wall_height for s in tall):
            raise _fail(scenario, f"{where} height must be positive and below the ceiling")
        if not all(0.0 <= c <= 1.0 for c in obstacle.color):
            raise _fail(scenario, f"{where} color must be three numbers 0-1")
        if not 0.0 <= obstacle.texture <= 1.0:
            raise _fail(scenario, f"{where} texture must be 0-1 (relative albedo variation)")


def _check_sensors(scenario: Scenario) -> None:
    venue = scenario.venue
    sensors = scenario.sensors
    if not 1 <= sensors.count <= 16:
        raise _fail(scenario, f"sensors.count must be 1-16; got {sensors.count}")
    if not 0.3 <= sensors.height < venue.wall_height:
        raise _fail(scenario, "sensors.height must be above 0.3 m and below the ceiling")
    if not -10.0 <= sensors.tilt_deg <= 80.0:
        raise _fail(scenario, f"sensors.tilt_deg must be -10 to 80 degrees; got {sensors.tilt_deg}")
    if not 0.0 <= sensors.clock_offset_max_s <= 10.0:
        raise _fail(scenario, "sensors.clock_offset_max_s must be 0-10 s")
    for i, pose in enumerate(sensors.poses):
        if math.dist(pose.at, pose.look_at) < 0.1:
            raise _fail(scenario, f"sensors.poses[{i}] must look at a point away from itself")
        if not _inside(scenario, pose.at[:2]) or not 0.0 < pose.at[2] < venue.wall_height:
            raise _fail(scenario, f"sensors.poses[{i}] must be inside the room")


def _check_people(scenario: Scenario) -> None:
    venue = scenario.venue
    people = scenario.people
    low, high = scenario.people_count_range()
    if not 0 <= low <= high <= 100:
        raise _fail(scenario, f"people.count must be 0-100 (or [min, max]); got {people.count}")
    if not 0.0 <= people.children <= 1.0:
        raise _fail(scenario, f"people.children is a fraction 0-1; got {people.children}")
    if min(people.standing, people.crossing, people.enter_leave) < 0:
        raise _fail(scenario, "people.standing, crossing and enter_leave must be >= 0")
    if any(size < 2 for size in people.groups):
        raise _fail(scenario, "people.groups lists group sizes, each at least 2")
    if people.enter_leave and not venue.doors:
        raise _fail(scenario, "people.enter_leave needs at least one door in venue.doors")
    if people.area is not None:
        x0, y0, x1, y1 = people.area
        if not (
            x0 < x1 and y0 < y1 and _inside(scenario, (x0, y0)) and _inside(scenario, (x1, y1))
        ):
            raise _fail(scenario, "people.area must be [xmin, ymin, xmax, ymax] inside the room")
    for i, route in enumerate(people.routes):
        if len(route) < 2 or not all(_inside(scenario, p, 0.2) for p in route):
            raise _fail(scenario, f"people.routes[{i}] needs at least 2 points inside the room")


def _check_board(scenario: Scenario) -> None:
    board = scenario.board
    if board is not None:
        if not (2 <= board.cols <= 20 and 2 <= board.rows <= 20) or board.cols == board.rows:
            raise _fail(
                scenario,
                "board.cols and board.rows must be 2-20 inner corners and differ "
                "(so the board's orientation is unambiguous)",
            )
        if not 0.01 <= board.square <= 0.5:
            raise _fail(scenario, f"board.square must be 0.01-0.5 m; got {board.square}")
        if not 0 <= board.floor_placements <= 20:
            raise _fail(scenario, "board.floor_placements must be 0-20")
        if board.intrinsics_sensor < -1 or not 1 <= board.intrinsics_placements <= 40:
            raise _fail(
                scenario,
                "board.intrinsics_sensor must be a sensor index (or -1) and "
                "board.intrinsics_placements 1-40",
            )
