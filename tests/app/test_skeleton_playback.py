"""Recording and playback carry skeletons: the operator switches skeletons on in the
Parameters dock of the window's embedded site (a real `optrack run --headless`), records a
take with the Recording dock, and opens it (File → Open recording…). The restarted site
keeps the skeleton stage on, with its parameters, and fits the skeletons again from the
recorded frames: they come back in the tracks table and the World view (OpenGL: run under
Xvfb)."""

from __future__ import annotations

import time

import pytest
import yaml

from app.main import build_parser, choose_source
from app.main_window import MainWindow
from optrack.recording import Recording
from optrack.runtime.venue import venue_recording
from optrack.skeleton.joints import JOINTS
from tests.conftest import free_port

from .conftest import VENUE

pytestmark = pytest.mark.opengl

SENSORS = ("kinect2_0", "kinect2_1")


@pytest.fixture
def window(qtbot, tmp_path):
    """The window and its embedded site: two sensors replaying the venue, skeletons off
    (the configuration file leaves them off; the operator turns them on live)."""
    venue = venue_recording(VENUE["scenario"], VENUE["seed"], VENUE["venue_seconds"])
    config = tmp_path / "site.yaml"
    config.write_text(
        yaml.safe_dump(
            {
                "bus": {"local_port": free_port()},
                "site": {
                    "name": "skelplay",
                    "sensors": ",".join(f"file://{venue}?loop=bounce#{s}" for s in SENSORS),
                    "report_s": 0.0,
                },
                "node": {
                    "state_dir": str(tmp_path / "state"),
                    "data_folder": str(tmp_path),
                    "status_period_s": 0.5,
                },
                "outputs": {"udp": ""},
                "skeleton": {"particles": 200, "init_layers": 6},
            }
        )
    )
    window = MainWindow()
    window.set_source(choose_source(build_parser().parse_args(["--config", str(config)]), window))
    window.show()
    yield window
    window.close()
    assert not window.embedded_site.running  # closing the window stopped the site


def joints_of(batch) -> list:
    """The skeletons of a batch that have joints (a lost one has none)."""
    return [s for s in batch.skeletons if s.joints]


def check_skeleton(skeleton) -> None:
    """Every joint named, a person's height, the head up where a head is (with the few
    particles of this test, under load, limbs may be far off: not checked)."""
    assert set(skeleton.joints) == set(JOINTS)
    assert 1.0 < skeleton.height < 2.2
    assert 0.5 < skeleton.joints["head"][2] < 2.3


def shown(window) -> bool:
    """Skeletons with joints drawn in the World view and stated in the tracks table's column."""
    model = window.tracks_table.model
    drawn = set(window.world.skeletons)
    return bool(drawn) and drawn <= set(model.skeletons) and model.skeleton_column


def test_a_take_recorded_with_skeletons_plays_back_with_skeletons(qtbot, window, tmp_path):
    try:
        record_and_play_back(qtbot, window, tmp_path)
    finally:
        # Closed here, before pytest-qt processes the pending events after the test: with
        # the site still sending, a loaded computer may never see the end of them.
        window.close()


def record_and_play_back(qtbot, window, tmp_path) -> None:
    """Switch skeletons on, record a take, open it: skeletons again, from its frames."""
    started = time.monotonic()

    def switch():  # the dock's control (its pages are rebuilt when a site says its stages)
        return window.parameters.editors["skeleton_live"]["enabled"]

    qtbot.waitUntil(
        lambda: sorted(window.source.nodes_running("skeleton_live")) == list(SENSORS),
        timeout=60000,
    )
    assert not switch().value()
    switch().check.click()  # the operator turns skeletons on
    qtbot.waitUntil(lambda: shown(window), timeout=60000)
    live = time.monotonic()
    for skeleton in window.tracks_table.model.skeletons.values():
        if skeleton.joints:
            check_skeleton(skeleton)

    panel = window.recording
    take = tmp_path / "take"
    panel.folder.setText(str(take))
    panel.record_button.click()
    qtbot.waitUntil(
        lambda: all(
            int(panel._status.get(s, {}).get("recording.frames") or 0) >= 20 for s in SENSORS
        ),
        timeout=30000,
    )
    panel.record_button.click()
    qtbot.waitUntil(lambda: panel.record_state.text().startswith("Recorded"), timeout=20000)
    assert sorted(Recording(take).sensor_ids) == list(SENSORS)
    recorded = time.monotonic()

    assert window.open_recording(str(take))
    qtbot.waitUntil(
        lambda: window.site_label.text().startswith(f"Playing {take.name} on"), timeout=60000
    )
    statuses: dict[str, dict] = {}
    batches: list = []
    window.source.status.connect(lambda node, values: statuses.__setitem__(node, values))
    window.source.skeletons.connect(batches.append)
    # The restarted site's detectors run the skeleton stage, and the dock shows it on.
    qtbot.waitUntil(lambda: set(SENSORS) <= set(statuses), timeout=30000)
    for sensor in SENSORS:
        assert statuses[sensor]["params"]["skeleton_live"]["enabled"] is True
        assert "playback.position_s" in statuses[sensor]["values"]  # playing the take
    assert switch().value()
    # Skeletons fitted again from the recorded frames: on the bus, drawn, in the table.
    qtbot.waitUntil(lambda: any(joints_of(b) for b in batches), timeout=60000)
    for skeleton in [s for b in batches for s in joints_of(b)]:
        check_skeleton(skeleton)
    qtbot.waitUntil(lambda: shown(window), timeout=30000)
    assert window.recording.source_label.text() == f"Playing {take}"
    print(
        f"skeletons live {live - started:.1f} s after the window opened, a take recorded by "
        f"{recorded - started:.1f} s, played back with skeletons by "
        f"{time.monotonic() - started:.1f} s"
    )
