"""The simulated operator of a simulated site (optrack.sim.operator), over loopback: its
scenes keep the site's sensors where they are, it carries the site's board, and refused
actions come back as one sentence."""

from __future__ import annotations

import time

import numpy as np
import pytest

from optrack.net.bus import Bus
from optrack.runtime.config import NODE_PARAMS
from optrack.runtime.node import CommandError, Node, send_command
from optrack.runtime.site_params import SITE_PARAMS
from optrack.sim.operator import OPERATOR_PARAMS, OperatorError, SceneSwitch, SimulatedOperator
from optrack.sim.sensor import SimulatedSensor
from optrack.sim.world import Simulation

BOARD = {"cols": 6, "rows": 5, "square": 0.15}


def test_the_simulated_operator_moves_every_node_into_a_scene_of_the_same_sensors(
    hub, make_client, tmp_path
):
    uris = [f"sim://calibration/{k}?sensors=3&id=cam{k}" for k in range(3)]
    site = SITE_PARAMS.create({"sensors": ",".join(uris)})
    operator = SimulatedOperator.for_site(site, uris, ["cam0", "cam1", "cam2"], tmp_path)
    assert operator is not None
    operator.serve(hub, send_command)
    nodes, switches = [], []
    for k, uri in enumerate(uris):
        own = SimulatedSensor.from_uri(uri)
        node = Node(hub, f"cam{k}", NODE_PARAMS.create(), {})
        switch = SceneSwitch(own)
        switch.register(node.add_command)
        nodes.append(node)
        switches.append(switch)
    client = make_client("wizard")
    try:
        with pytest.raises(CommandError, match="cannot 'dance'"):
            send_command(client, "site", "operator", {"action": "dance"})
        with pytest.raises(CommandError, match="8x6"):
            send_command(client, "site", "operator", {"action": "move_board", "cols": 8, "rows": 6})
        reply = send_command(client, "site", "operator", {"action": "lay_board", **BOARD})
        assert reply["scene"].endswith("lay_board")
        taken: list = [None] * 3
        deadline = time.monotonic() + 30
        while any(t is None for t in taken) and time.monotonic() < deadline:
            for k, switch in enumerate(switches):
                taken[k] = taken[k] or switch.take(lambda sentence: None)
            time.sleep(0.05)
        truth = Simulation("calibration", sensors=3).sensors
        for k, sensor in enumerate(taken):
            assert sensor is not None and reply["scene"] in sensor.info.uri
            assert sensor.info.id == f"cam{k}"
            assert np.allclose(sensor.info.world_T_camera, truth[k].world_T_camera)
            assert sensor.simulation.scenario.people.count == 0
            # Only the floor placements, the operator starting at the first: no held ones
            # to walk through (or to simulate) before the floor page sees the board.
            steps = sensor.simulation.operator.steps
            assert [s.kind for s in steps] == ["floor"] * 3
            assert np.allclose(sensor.simulation.operator.start_point, steps[0].operator_spot)
            # The board lies still at a floor place the operator's floor hold (one
            # sensor's still view is enough there).
            floor_hold = OPERATOR_PARAMS.defaults()["floor_hold_s"]
            assert sensor.simulation.operator.params.hold_seconds == floor_hold
        assert operator.status_values()["operator"] == "lay_board"
        send_command(client, "site", "operator", {"action": "people"})
        deadline = time.monotonic() + 10
        back = None
        while back is None and time.monotonic() < deadline:
            back = switches[0].take(lambda sentence: None)
            time.sleep(0.05)
        assert back is switches[0].own
    finally:
        for node in nodes:
            node.close()


def test_the_simulated_operator_shows_the_board_to_one_sensor_all_over_its_image(
    hub, make_client, tmp_path
):
    """The intrinsics page's scene: every placement is seen whole by the one sensor asked
    for, the board's centre in several cells of its image, turned several ways (up to 45
    degrees) and held low and high (the views must pin the lens down: the page calls it
    good by calibration_intrinsics.good_std_px); the site status says when it is done (the
    wizard's backend sends the operator round again while the lens is not good)."""
    from optrack.geometry import invert, transform_points

    uris = [f"sim://calibration/{k}?sensors=2&id=cam{k}" for k in range(2)]
    site = SITE_PARAMS.create({"sensors": ",".join(uris)})
    operator = SimulatedOperator.for_site(site, uris, ["cam0", "cam1"], tmp_path)
    operator.serve(hub, send_command)
    nodes, switches = [], []
    for k, uri in enumerate(uris):
        node = Node(hub, f"cam{k}", NODE_PARAMS.create(), {})
        switch = SceneSwitch(SimulatedSensor.from_uri(uri))
        switch.register(node.add_command)
        nodes.append(node)
        switches.append(switch)
    client = make_client("wizard")
    try:
        with pytest.raises(CommandError, match="one of the site's sensors"):
            send_command(client, "site", "operator", {"action": "show_board", "sensor": "cam7"})
        reply = send_command(
            client, "site", "operator", {"action": "show_board", "sensor": "cam1", **BOARD}
        )
        assert reply["scene"].endswith("show_board")
        deadline, sensor = time.monotonic() + 30, None
        while sensor is None and time.monotonic() < deadline:
            sensor = switches[1].take(lambda sentence: None)
            time.sleep(0.05)
        assert sensor is not None and reply["scene"] in sensor.info.uri
    finally:
        for node in nodes:
            node.close()
    steps = sensor.simulation.operator.steps
    places = OPERATOR_PARAMS.defaults()["intrinsics_places"]
    assert len(steps) == places and all(s.kind == "hold" and s.sensors == (1,) for s in steps)
    assert sensor.simulation.operator.params.hold_seconds == 1.5
    truth = Simulation("calibration", sensors=2).sensors[1]
    k = truth.model.intrinsics
    cells, turns = set(), []
    for step in steps:
        centre = transform_points(invert(truth.world_T_camera), step.world_T_board[:3, 3][None])[0]
        u, v = k.fx * centre[0] / centre[2] + k.cx, k.fy * centre[1] / centre[2] + k.cy
        assert 0 <= u < k.width and 0 <= v < k.height
        cells.add((int(3 * u / k.width), int(3 * v / k.height)))
        # The printed face looks along -z of the board; the angle it makes with the camera.
        to_camera = truth.world_T_camera[:3, 3] - step.world_T_board[:3, 3]
        cos = -step.world_T_board[:3, 2] @ to_camera / np.linalg.norm(to_camera)
        turns.append(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
    assert len(cells) >= 5
    assert max(turns) - min(turns) >= 35.0
    heights = [step.world_T_board[2, 3] for step in steps]
    assert max(heights) - min(heights) >= 0.6
    assert float(operator.status_values()["operator.until"]) > time.time()


def test_the_simulated_operator_carries_the_sites_board_and_needs_one(tmp_path):
    """The board is the command's; what the command leaves out comes from the site
    scenario's board (no board size of the operator's own); a site whose scenario has no
    board needs the command to give it whole."""
    import yaml

    from optrack.errors import UserError

    venue = [f"sim://mixed/{k}?id=cam{k}" for k in range(2)]
    site = SITE_PARAMS.create({"sensors": ",".join(venue)})
    operator = SimulatedOperator.for_site(site, venue, ["cam0", "cam1"], tmp_path)
    with pytest.raises(UserError, match="needs the board's cols") as refused:
        operator.command({"action": "move_board"})
    assert str(refused.value).endswith(".")
    uris = [f"sim://calibration/{k}?sensors=2&id=cam{k}" for k in range(2)]
    site = SITE_PARAMS.create({"sensors": ",".join(uris)})
    operator = SimulatedOperator.for_site(site, uris, ["cam0", "cam1"], tmp_path)
    reply = operator.command({"action": "lay_board", "cols": 8})
    scene = tmp_path / f"{reply['scene']}.yaml"
    deadline = time.monotonic() + 30
    while not scene.is_file() and time.monotonic() < deadline:
        time.sleep(0.05)
    board = yaml.safe_load(scene.read_text())["board"]
    assert (board["cols"], board["rows"], board["square"]) == (8, 5, 0.15)


def test_the_extrinsics_scene_holds_the_board_only_where_two_sensors_see_it(tmp_path):
    """move_board with pairs (the extrinsics page): the scene's operator starts at the first
    place two sensors share and holds the board only at such places."""
    uris = [f"sim://calibration/{k}?sensors=3&id=cam{k}" for k in range(3)]
    site = SITE_PARAMS.create({"sensors": ",".join(uris)})
    operator = SimulatedOperator.for_site(site, uris, ["cam0", "cam1", "cam2"], tmp_path)
    reply = operator.command({"action": "move_board", "pairs": True, **BOARD})
    scene = tmp_path / f"{reply['scene']}.yaml"
    deadline = time.monotonic() + 30
    while not scene.is_file() and time.monotonic() < deadline:
        time.sleep(0.05)
    simulation = Simulation(str(scene), sensors=3)
    steps = simulation.operator.steps
    assert steps and all(s.kind == "hold" and len(s.sensors) == 2 for s in steps)
    assert np.allclose(simulation.operator.start_point, steps[0].operator_spot)
    # Each pair at two places (the extrinsics page asks every sensor for two shared board
    # poses), sim_board.place_spacing apart.
    spacing = simulation.board.params.place_spacing
    for pair in {s.sensors for s in steps}:
        places = [s.world_T_board[:3, 3] for s in steps if s.sensors == pair]
        assert len(places) == 2 and np.linalg.norm(places[0] - places[1]) >= spacing - 0.01
    # The site status says when every placement is made (the wizard's backend asks the
    # operator to go round again after it while a sensor needs more).
    deadline = time.monotonic() + 30
    while not operator.status_values()["operator.until"] and time.monotonic() < deadline:
        time.sleep(0.05)
    until = float(operator.status_values()["operator.until"])
    assert until > time.time() + 5 * len(steps)  # at least the 5 s holds
    longer = operator.command({"action": "move_board", "pairs": True, "hold": 9.0, **BOARD})
    deadline = time.monotonic() + 30
    while (
        operator.status_values()["operator.scene"] != longer["scene"]
        or not (operator.status_values()["operator.until"])
    ):
        assert time.monotonic() < deadline
        time.sleep(0.05)
    assert float(operator.status_values()["operator.until"]) > until + 3.5 * len(steps)
    with pytest.raises(OperatorError, match="0 to 60 s"):
        operator.command({"action": "move_board", "pairs": True, "hold": 90, **BOARD})


def _site_config(folder, name: str, sensors: str) -> str:
    """A site config on a free port; no ``sensors``: the embedded venue (``make run``)."""
    import yaml

    from .conftest import free_port

    config = folder / f"{name}.yaml"
    site = {"name": name, "report_s": 10.0, **({"sensors": sensors} if sensors else {})}
    config.write_text(
        yaml.safe_dump(
            {
                "bus": {"local_port": free_port(), "connect_timeout_s": 30.0},
                "site": site,
                "node": {"state_dir": str(folder / "state"), "status_period_s": 0.5},
            }
        )
    )
    return str(config)


def _live_calibration(config: str, count: int):
    """The wizard's backend joined to the site of ``config`` once its ``count`` detector
    nodes answer."""
    from optrack.calibration.board import Checkerboard
    from optrack.errors import UserError
    from optrack.params import load_config
    from optrack.runtime.calibration_live import LiveCalibration

    loaded = load_config(config)
    bus = Bus(str(loaded["site"].name), "wizard", loaded["bus"])
    deadline = time.monotonic() + 120
    while True:
        try:
            live = LiveCalibration(bus, Checkerboard(6, 5, 0.15))
            if len(live.sensors) == count:
                return bus, live
            live.close()
        except UserError:
            if time.monotonic() > deadline:
                bus.close()
                raise
        time.sleep(0.5)


# `optrack calibrate live`'s backend on one site: the same backend and operator calibrate
# the default, 2-, 4- and 6-sensor sites through the wizard in tests/app/test_wizard_site.py
# (the newcomer test), each to the same 2 cm / 0.3 degree target.
SITES = {
    # sim:// sensors of a scenario (its first N)
    "two": ("calibration", 2, ""),
}


@pytest.mark.parametrize("site", sorted(SITES))
def test_the_headless_wizard_calibrates_every_camera_of_a_simulated_site(site, processes, tmp_path):
    """`optrack calibrate live`'s backend against a running site whose simulated operator
    plans its board from the sensors' views: every sensor shares views with a calibrated
    one, and every camera ends within 2 cm and 0.3 degrees of the simulation's truth."""
    from optrack.calibration.files import load_calibration
    from optrack.calibration.quality import calibration_errors
    from optrack.runtime.calibration_headless import HeadlessPlan, calibrate_headless

    scenario, count, options = SITES[site]
    truth = {s.id: s.world_T_camera for s in Simulation(scenario, people=0, sensors=count).sensors}
    uris = [
        f"sim://{scenario}/{k}?sensors={count}{options}&id={name}" for k, name in enumerate(truth)
    ]
    config = _site_config(tmp_path, site, "" if options is None else ",".join(uris))
    processes.start(
        ["optrack.cli", "run", "--headless", "--seconds", "600", "--config", config], site
    )
    bus, live = _live_calibration(config, count)
    said: list[str] = []
    try:
        assert live.state().message.startswith("Not capturing yet: the board and floor pages")
        plan = HeadlessPlan(out=str(tmp_path / "network.yaml"), extrinsics_s=240.0, publish=False)
        payload = calibrate_headless(live, plan, said.append)
    finally:
        live.close()
        bus.close()
    assert payload["uncalibrated"] == [], said[-5:]
    calibration = load_calibration(payload["out"])
    assert calibration.world == "floor"
    assert sorted(calibration.sensors) == sorted(truth)
    errors = calibration_errors({n: calibration.pose(n) for n in truth}, truth)
    assert errors.max_position_error_m <= 0.02, errors.as_dict()
    assert errors.max_rotation_error_deg <= 0.3, errors.as_dict()


@pytest.mark.parametrize(
    ("scenario", "count"), [("mixed", 3), ("mixed", 4), ("mixed", 6), ("calibration", 5)]
)
def test_the_held_board_joins_every_sensor_to_the_others(scenario, count):
    """The plan's boards seen by two sensors at once join all sensors (one chain of shared
    views), whatever the layout, and none is hidden behind the venue (a pillar in front of
    the middle of the pattern included: every inner corner is in sight)."""
    import msgspec
    import open3d as o3d

    from optrack.geometry import transform_points
    from optrack.sim.scenario import BoardSpec, PeopleSpec, load_scenario

    base = load_scenario(scenario)
    board = base.board or BoardSpec(cols=6, rows=5, square=0.15, floor_placements=0)
    sim = Simulation(
        msgspec.structs.replace(base, people=PeopleSpec(count=0), board=board), sensors=count
    )
    held = [s for s in sim.operator.steps if s.kind == "hold"]
    joined = {0}
    for _ in range(count):
        for step in held:
            if len(step.sensors) > 1 and joined & set(step.sensors):
                joined |= set(step.sensors)
    assert joined == set(range(count))
    for step in held:
        corners = transform_points(step.world_T_board, sim.board.pattern.object_points)
        for k in step.sensors:
            origin = sim.sensors[k].world_T_camera[:3, 3]
            rays = np.column_stack([np.tile(origin, (len(corners), 1)), corners - origin])
            hidden = sim.static.scene.test_occlusions(
                o3d.core.Tensor(rays.astype(np.float32)), tnear=0.0, tfar=0.99
            )
            assert not hidden.numpy().any(), (step.sensors, k)
