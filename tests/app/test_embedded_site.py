"""The window against the embedded site: `optrack run --headless` started by the window,
joined over the bus on loopback (OpenGL: run under Xvfb). The issue's done-when checks."""

import socket
import time

import pytest
import yaml

from app.main import build_parser, choose_source
from app.main_window import MainWindow
from optrack.runtime.site import venue_recording

pytestmark = pytest.mark.opengl

VENUE = {"scenario": "mixed", "seed": 0, "venue_seconds": 4.0}


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@pytest.fixture(scope="module")
def site_config(tmp_path_factory):
    """A site on its own loopback port, its venue rendered beforehand (once per computer,
    cached), so that the timing below is the site's start, not a one-time render."""
    venue_recording(VENUE["scenario"], VENUE["seed"], VENUE["venue_seconds"])
    path = tmp_path_factory.mktemp("site") / "site.yaml"
    path.write_text(
        yaml.safe_dump(
            {
                "bus": {"local_port": free_port()},
                "site": {**VENUE, "name": "guitest", "report_s": 0.0},
                "outputs": {"udp": ""},
            }
        )
    )
    return path


@pytest.fixture
def window(qtbot, site_config):
    window = MainWindow()
    qtbot.addWidget(window)
    window.set_source(
        choose_source(build_parser().parse_args(["--config", str(site_config)]), window)
    )
    window.show()
    yield window
    window.shut_down()
    assert not window.embedded_site.running  # closing the window stops the site


def test_embedded_site_tracks_reach_the_table_and_top_view_within_15_s(qtbot, window):
    started = time.monotonic()
    qtbot.waitUntil(
        lambda: (
            window.tracks_table.model.rowCount() > 0 and bool(window.top_view.track_positions())
        ),
        timeout=15000,
    )
    elapsed = time.monotonic() - started
    print(f"first tracks in the table and the top view {elapsed:.1f} s after the window opened")
    print("DEBUG stages", window.source._node_stages, window.sensors.table.rowCount())
    assert window.site_label.text() == "Embedded site 'guitest' on this computer"
    table_ids = {track.id for track in window.tracks_table.model.tracks}
    assert table_ids == set(window.top_view.track_positions())


def test_moving_a_slider_changes_the_detectors_parameter(qtbot, window):
    t0 = time.monotonic()
    print(f"DEBUG test2 starts {t0 - window.opened_at:.1f} after open", window.source._node_stages)
    statuses = {}
    window.source.status.connect(lambda node, values: statuses.__setitem__(node, values))
    qtbot.waitUntil(lambda: bool(window.source.nodes_running("detection")), timeout=30000)
    print(f"DEBUG nodes {time.monotonic() - t0:.1f}")
    voxel = window.parameters.editors["detection"]["voxel_size"]
    target = 0.08 if voxel.value() != 0.08 else 0.07
    voxel.slider.setValue(voxel.slider.value() + round((target - voxel.value()) / 0.01))
    assert voxel.value() == target
    detectors = window.source.nodes_running("detection")

    def applied() -> bool:
        return all(
            statuses.get(node, {}).get("params", {}).get("detection", {}).get("voxel_size")
            == target
            for node in detectors
        )

    print(f"DEBUG moved {time.monotonic() - t0:.1f}")
    moved = time.monotonic()
    qtbot.waitUntil(applied, timeout=10000)
    print(f"every detector reported the new voxel size {time.monotonic() - moved:.1f} s later")
    print(f"DEBUG end {time.monotonic() - t0:.1f}")


def test_an_output_added_in_the_panel_streams_tracks_to_it(qtbot, window):
    receiver = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    receiver.bind(("127.0.0.1", 0))
    receiver.settimeout(0.2)
    address = f"127.0.0.1:{receiver.getsockname()[1]}"
    try:
        qtbot.waitUntil(lambda: bool(window.source.nodes_running("outputs")), timeout=30000)
        window.outputs.kind.setCurrentIndex(window.outputs.kind.findData("udp"))
        window.outputs.address.setText(address)
        window.outputs.add_button.click()
        qtbot.waitUntil(
            lambda: any(d["address"] == address for d in window.outputs.destinations),
            timeout=10000,
        )
        datagrams = []

        def received() -> bool:
            try:
                datagrams.append(receiver.recv(65536))
            except TimeoutError:
                pass
            return bool(datagrams)

        added = time.monotonic()
        qtbot.waitUntil(received, timeout=10000)
        print(f"first datagram {time.monotonic() - added:.1f} s after the destination appeared")
        assert datagrams[0].startswith(b'{"header"')
    finally:
        receiver.close()
