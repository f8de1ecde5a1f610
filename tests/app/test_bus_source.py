"""The GUI's bus client against a real Zenoh hub on loopback (no display needed)."""

import threading
import time

import pytest
from PySide6.QtCore import QObject, QTimer, Slot

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


class LoadedWindow(QObject):
    """A window whose thread takes 5 ms to draw each batch."""

    def __init__(self) -> None:
        super().__init__()
        self.shown: list[int] = []

    @Slot(object)
    def draw(self, batch: TrackBatch) -> None:
        self.shown.append(batch.seq)
        time.sleep(0.005)


def test_a_flood_of_tracks_never_starves_a_loaded_window_and_the_newest_is_shown(qtbot, hub):
    """A site sending tracks for 1.5 s ten times faster than the window's thread draws
    them (5 ms a batch here): the event loop keeps turning (a 20 ms timer keeps firing),
    the tracks signal fires at most once per pass, in order, and the newest batch is shown
    as soon as the flood ends (queued one signal each, they would take seconds more)."""
    bus, params = hub
    source = joined(qtbot, params)
    window = LoadedWindow()  # lives on this (the window's) thread, as the real one
    shown = window.shown
    ticks: list[float] = []
    timer = QTimer()
    timer.timeout.connect(lambda: ticks.append(time.monotonic()))
    try:
        source.tracks.connect(window.draw)
        probe = TracksMessage(batch=TrackBatch(0.0))  # until Zenoh routes the subscription
        qtbot.waitUntil(
            lambda: bus.publish(bus.keys.tracks, probe, realtime=False) or bool(shown),
            timeout=5000,
        )
        sent: list[tuple[int, float]] = []  # the last batch's seq, when the flood ended

        def flood() -> None:
            seq, end = 0, time.monotonic() + 1.5
            while time.monotonic() < end:  # about 2000 batches a second
                for _ in range(20):
                    seq += 1
                    batch = TrackBatch(float(seq), seq, tracks=[Track(1, 0.0, 0.0, 1.7)])
                    bus.publish(bus.keys.tracks, TracksMessage(batch=batch), realtime=False)
                time.sleep(0.01)
            sent.append((seq, time.monotonic()))

        shown.clear()
        timer.start(20)
        started = time.monotonic()
        threading.Thread(target=flood, daemon=True).start()
        caught_up: list[float] = []

        def newest_shown() -> bool:
            if sent and shown[-1:] == [sent[0][0]]:
                caught_up.append(time.monotonic())
                return True
            return False

        qtbot.waitUntil(newest_shown, timeout=60000)
        timer.stop()
        (last, ended), lag = sent[0], caught_up[0] - sent[0][1]
        assert shown == sorted(set(shown))  # in order, none twice
        assert len(shown) <= last // 3, (len(shown), last)
        during = [t for t in ticks if t <= ended]
        gaps = [b - a for a, b in zip([started, *during], during, strict=False)]
        assert during and max(gaps) < 1.0, (max(gaps), last)
        assert lag < 2.0, (lag, last)
        assert source.client.replaced >= last - len(shown)
    finally:
        timer.stop()
        source.close()
