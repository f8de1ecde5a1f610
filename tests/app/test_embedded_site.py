"""The window against the embedded site: `optrack run --headless` started by the window,
joined over the bus on loopback (OpenGL: run under Xvfb). The issue's done-when checks."""

import socket
import time

import pytest

from app.main import build_parser, choose_source
from app.main_window import MainWindow

pytestmark = pytest.mark.opengl


@pytest.fixture(scope="module")
def window(qapp, site_config):
    """One window and its embedded site for the tests of this file (a site takes seconds
    to start on a small computer)."""
    window = MainWindow()
    args = build_parser().parse_args(["--config", str(site_config)])
    window.set_source(choose_source(args, window))
    window.show()
    window.opened_at = time.monotonic()
    yield window
    window.close()
    assert not window.embedded_site.running  # closing the window stopped the site


def test_embedded_site_tracks_reach_the_table_and_top_view_within_15_s(qtbot, window):
    started = window.opened_at
    qtbot.waitUntil(
        lambda: (
            window.tracks_table.model.rowCount() > 0 and bool(window.top_view.track_positions())
        ),
        timeout=15000,
    )
    elapsed = time.monotonic() - started
    print(f"first tracks in the table and the top view {elapsed:.1f} s after the window opened")
    assert window.site_label.text() == "Embedded site 'guitest' on this computer"
    table_ids = {track.id for track in window.tracks_table.model.tracks}
    assert table_ids == set(window.top_view.track_positions())


def test_moving_a_slider_changes_the_detectors_parameter(qtbot, window):
    statuses = {}
    window.source.status.connect(lambda node, values: statuses.__setitem__(node, values))
    qtbot.waitUntil(lambda: bool(window.source.nodes_running("detection")), timeout=30000)
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

    moved = time.monotonic()
    qtbot.waitUntil(applied, timeout=10000)
    print(f"every detector reported the new voxel size {time.monotonic() - moved:.1f} s later")


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
        try:  # the site's next status lists it (a busy 2-core computer takes seconds)
            qtbot.waitUntil(
                lambda: any(d["address"] == address for d in window.outputs.destinations),
                timeout=30000,
            )
        except qtbot.TimeoutError:
            raise AssertionError(
                f"{address} never appeared in the outputs panel: it lists "
                f"{window.outputs.destinations}; its message {window.outputs.message.text()!r}; "
                f"the log ends {window.log_panel.lines()[-5:]}"
            ) from None
        datagrams = []

        def received() -> bool:
            try:
                datagrams.append(receiver.recv(65536))
            except TimeoutError:
                pass
            return bool(datagrams)

        added = time.monotonic()
        qtbot.waitUntil(received, timeout=30000)
        print(f"first datagram {time.monotonic() - added:.1f} s after the destination appeared")
        assert datagrams[0].startswith(b'{"header"')
    finally:
        receiver.close()
