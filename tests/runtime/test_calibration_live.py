"""The live calibration (the wizard's backend) against a running simulated site, as the
wizard drives it: `optrack run` with three simulated sensors, its simulated operator moving
the board and laying it on the floor when asked, LiveCalibration grouping the nodes' board
views and solving; the result is compared with the simulation's truth, saved, loaded and
sent to the nodes."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from optrack.calibration.board import Checkerboard
from optrack.calibration.files import load_calibration
from optrack.calibration.live import LiveCalibrationError, LiveState
from optrack.calibration.quality import calibration_errors
from optrack.errors import UserError
from optrack.net.bus import Bus
from optrack.net.config import BUS_PARAMS
from optrack.runtime.calibration_live import LiveCalibration
from optrack.sim.world import Simulation

SENSORS = 3
NAMES = [f"cam{k}" for k in range(SENSORS)]
BOARD = Checkerboard(6, 5, 0.15)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """`optrack run --headless` with three live simulated sensors of `calibration`."""
    folder = tmp_path_factory.mktemp("live")
    port = _free_port()
    uris = ",".join(f"sim://calibration/{k}?sensors={SENSORS}&id={n}" for k, n in enumerate(NAMES))
    config = folder / "site.yaml"
    config.write_text(
        yaml.safe_dump(
            {
                "bus": {"local_port": port, "connect_timeout_s": 30.0},
                "site": {"name": "livetest", "sensors": uris, "report_s": 10.0},
                "node": {"state_dir": str(folder / "state"), "status_period_s": 0.5},
            }
        )
    )
    log = (folder / "site.log").open("wb")
    process = subprocess.Popen(
        [sys.executable, "-m", "optrack.cli", "run", "--headless", "--seconds", "400"]
        + ["--config", str(config)],
        stdout=log,
        stderr=subprocess.STDOUT,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
        start_new_session=True,
    )
    bus = Bus(
        "livetest", "wizard", BUS_PARAMS.create({"local_port": port, "connect_timeout_s": 30})
    )
    try:
        yield bus, folder, config
    finally:
        bus.close()
        process.send_signal(signal.SIGINT)
        try:
            process.wait(30)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()
        log.close()


def _connect(bus: Bus) -> LiveCalibration:
    deadline = time.monotonic() + 90
    while True:
        try:
            live = LiveCalibration(bus, BOARD)
            if len(live.sensors) == SENSORS:
                return live
            live.close()
        except UserError:
            if time.monotonic() > deadline:
                raise
        time.sleep(0.5)


def _until(live: LiveCalibration, done, seconds: float) -> LiveState:
    deadline = time.monotonic() + seconds
    while True:
        state = live.state()
        if done(state) or time.monotonic() > deadline:
            return state
        time.sleep(0.25)


def test_live_calibration_puts_every_camera_within_3_cm_and_half_a_degree(site, tmp_path):
    bus, folder, _ = site
    live = _connect(bus)
    try:
        assert live.sensors == NAMES and live.simulated
        live.start("extrinsics")
        state = _until(
            live,
            lambda s: s.instants >= 6 and all(v.calibrated for v in s.sensors.values()),
            120,
        )
        assert all(v.calibrated for v in state.sensors.values()), state
        assert state.covisibility and state.operator == "move_board"
        seen = [v for v in state.sensors.values() if v.image is not None]
        assert seen and seen[0].image.ndim == 3 and seen[0].image.dtype == np.uint8
        assert all(v.world_T_camera is not None for v in state.sensors.values())
        live.stop()
        live.start("floor")
        state = _until(live, lambda s: s.floor_views >= 2, 90)
        assert state.floor_views >= 2 and state.operator == "lay_board"
        live.stop()
        calibration = live.solve(lambda fraction, sentence: None)
        assert live.result is not None and live.result.world == "floor"
        truth = {
            n: s.world_T_camera
            for n, s in zip(NAMES, Simulation("calibration", sensors=SENSORS).sensors, strict=True)
        }
        estimated = {n: calibration.pose(n) for n in NAMES}
        errors = calibration_errors(estimated, truth)
        assert errors.max_position_error_m <= 0.03, errors.as_dict()
        assert errors.max_rotation_error_deg <= 0.5, errors.as_dict()
        assert errors.ground_error_deg <= 0.5 and errors.ground_error_m <= 0.03, errors.as_dict()

        path = live.save(tmp_path / "network.yaml")
        saved = load_calibration(path)
        assert sorted(saved.sensors) == NAMES and saved.world == "floor"
        assert saved.board is not None and (saved.board.cols, saved.board.rows) == (6, 5)
        live.save(path)
        assert (tmp_path / "network.yaml.bak").is_file()

        live.publish()
        stored = folder / "state" / "cam0" / "calibration.yaml"
        deadline = time.monotonic() + 15
        while time.monotonic() < deadline:
            if stored.is_file() and load_calibration(stored).id == saved.id:
                break
            time.sleep(0.2)
        assert load_calibration(stored).id == saved.id
        assert np.allclose(load_calibration(stored).pose("cam1"), calibration.pose("cam1"))
    finally:
        live.close()


def test_a_phase_or_sensor_that_does_not_exist_is_refused_in_one_sentence(site):
    bus, _, _ = site
    live = _connect(bus)
    try:
        with pytest.raises(LiveCalibrationError, match="phase 'sideways' is unknown"):
            live.start("sideways")
        with pytest.raises(LiveCalibrationError, match="needs one of the site's sensors"):
            live.start("intrinsics", "cam9")
        with pytest.raises(UserError, match="solve the extrinsics and the floor first"):
            live.refine(lambda fraction, sentence: None)
        with pytest.raises(UserError, match="nothing to save yet"):
            live.save(Path("never.yaml"))
    finally:
        live.close()


def test_the_headless_wizard_says_in_one_sentence_when_no_site_answers(tmp_path):
    config = tmp_path / "nowhere.yaml"
    config.write_text(
        yaml.safe_dump({"bus": {"local_port": _free_port(), "connect_timeout_s": 1.0}})
    )
    result = subprocess.run(
        [sys.executable, "-m", "optrack.cli", "calibrate", "live", "--site", "nowhere"]
        + ["--config", str(config), "--out", str(tmp_path / "n.yaml"), "--json"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 1
    assert result.stdout == ""
    last = result.stderr.strip().splitlines()[-1]
    assert "site" in last and last.endswith(".")
