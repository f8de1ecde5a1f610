"""The GUI's bus client against a real Zenoh hub on loopback (no display needed)."""

import pytest

from app.bus_source import BusSource
from optrack.net import BUS_PARAMS, Bus, ParamsMessage, StatusMessage, TracksMessage
from optrack.types import Track, TrackBatch

from .conftest import free_port


@pytest.fixture
def hub():
    """A node hosting a local site's hub on a free loopback port (like the tracker node)."""
    params = BUS_PARAMS.create({"local_port": free_port(), "connect_timeout_s": 5.0})
    bus = Bus("guitest", "tracker", params, host=True)
    yield bus, params
    bus.close()


def door_status(**fields) -> StatusMessage:
    """The status of a detector node named after its sensor 'door'."""
    return StatusMessage(
        node="detector-door",
        role="detector",
        state="running",
        stamp=1.0,
        sensor="door",
        params={"detection": {"voxel_size": 0.06}},
        **fields,
    )


def joined(qtbot, params) -> BusSource:
    source = BusSource("guitest", params)
    with qtbot.waitSignal(source.connection, timeout=10000) as connected:
        pass
    assert connected.args == ["Site 'guitest' on this computer"]
    return source


def test_tracks_and_status_from_the_bus_become_signals(qtbot, hub):
    bus, params = hub
    source = joined(qtbot, params)
    try:
        batch = TrackBatch(stamp=12.5, seq=3, tracks=[Track(4, 1.0, -2.0, 1.7, age=2.0)])
        with qtbot.waitSignal(source.tracks, timeout=5000) as got:
            # Zenoh routes a new subscription within milliseconds; publish until it does.
            qtbot.waitUntil(
                lambda: (
                    bus.publish(bus.keys.tracks, TracksMessage(batch=batch)) or got.signal_triggered
                ),
                timeout=5000,
            )
        assert got.args == [batch]
        status = door_status(fps=29.5)
        with qtbot.waitSignals([source.schemas, source.status], timeout=5000) as got:
            bus.publish(bus.keys.status("detector-door"), status)
        assert source.nodes_running("detection") == ["detector-door"]
    finally:
        source.close()


def test_a_parameter_change_reaches_the_node_that_runs_the_stage(qtbot, hub):
    bus, params = hub
    received = []
    bus.subscribe(bus.keys.params("detector-door"), ParamsMessage, lambda m, _: received.append(m))
    source = joined(qtbot, params)
    try:
        status = door_status()
        qtbot.waitUntil(
            lambda: (
                bus.publish(bus.keys.status("detector-door"), status)
                or source.nodes_running("detection") == ["detector-door"]
            ),
            timeout=5000,
        )
        source.set_params("detection", {"voxel_size": 0.08})
        qtbot.waitUntil(lambda: len(received) == 1, timeout=5000)
        assert received[0].updates == {"detection": {"voxel_size": 0.08}}
        assert received[0].sender == source.node
    finally:
        source.close()


def test_no_hub_is_explained_in_a_sentence(qtbot):
    params = BUS_PARAMS.create({"local_port": free_port(), "connect_timeout_s": 0.5})
    source = BusSource("guitest", params)
    with qtbot.waitSignal(source.log, timeout=10000) as said:
        pass
    assert said.args[0] == "error"
    assert "cannot reach the local site's hub" in said.args[1]
    assert not source.connected
    source.close()
