"""The window against a real peer site on loopback (`optrack node track` in its own
process): joined with the site's keys and a station's identity, or told in one sentence
what it lacks; an insecure site shown as such in the status bar."""

from __future__ import annotations

import argparse

import pytest
import yaml

from app.main import choose_source
from app.source import SiteSource
from app.widgets.insecure_warning import INSECURE_TEXT
from optrack.net.security import init_site
from tests.runtime.conftest import Processes, free_port

LINKS = {"multicast_scouting": False, "gossip": False}


@pytest.fixture
def window(qtbot):
    """The operator's window (not shown: its status bar's widgets are what is looked at)."""
    from app.main_window import MainWindow

    window = MainWindow()
    qtbot.addWidget(window)
    yield window
    window.source.close()


@pytest.fixture
def processes(tmp_path):
    p = Processes(tmp_path)
    yield p
    p.stop_all()


def write(path, values: dict) -> str:
    path.write_text(yaml.safe_dump(values))
    return str(path)


def tracker(processes: Processes, tmp_path, bus: dict, *args: str) -> str:
    """A tracker node of site 'lab' listening on a free loopback port; its endpoint."""
    port = free_port()
    config = write(
        tmp_path / "tracker.yaml",
        {
            "bus": {"mode": "peer", "listen": f"tcp/127.0.0.1:{port}", **LINKS, **bus},
            "node": {"state_dir": str(tmp_path / "state"), "status_period_s": 0.2},
            "outputs": {"udp": ""},
        },
    )
    processes.start(
        ["optrack.cli", "node", "track", "--site", "lab", "--config", config, *args], "tracker"
    )
    return f"tcp/127.0.0.1:{port}"


def connect(window, tmp_path, endpoint: str, bus: dict):
    """`optrack gui --connect ENDPOINT --config FILE` (the file holding ``bus``)."""
    config = write(tmp_path / "station.yaml", {"site": {"name": "lab"}, "bus": {**LINKS, **bus}})
    args = argparse.Namespace(no_site=False, join=False, connect=endpoint, config=config, site=None)
    source = choose_source(args, window)
    window.set_source(source)
    return source


def said(window, qtbot, level: str) -> str:
    """The first line of ``level`` in the window's log (waiting for it)."""
    prefix = f"{level.capitalize()}: "
    found = lambda: [line for line in window.log_panel.lines() if prefix in line]  # noqa: E731
    qtbot.waitUntil(lambda: bool(found()), timeout=30000)
    return found()[0].split(prefix, 1)[1]


def test_a_station_joins_a_peer_site_with_its_keys_or_is_told_what_it_lacks(
    qtbot, window, tmp_path, processes
):
    keys = tmp_path / "lab-keys"
    init_site(keys, nodes=["tracker"], stations=["op1"], site="lab")
    endpoint = tracker(processes, tmp_path, {"keys": str(keys)})
    source = connect(window, tmp_path, endpoint, {"keys": str(keys), "identity": "op1"})
    qtbot.waitUntil(lambda: "tracker" in source.client.statuses(), timeout=60000)
    assert window.site_label.text() == "Site 'lab' on the network (peer)"
    assert not source.insecure
    window.insecure_warning.check()
    assert window.insecure_warning.isHidden()
    assert not [line for line in window.log_panel.lines() if "Error: " in line]
    source.close()

    connect(window, tmp_path, endpoint, {"keys": str(keys)})
    assert said(window, qtbot, "error") == (
        f"bus.identity is empty: set it to this station's name in the site keys in {keys} "
        f"(its stations: op1), or add one with 'optrack site init --out {keys} --stations "
        "NAME' on the computer that holds ca-key.pem."
    )
    window.source.close()
    window.log_panel.list.clear()
    nowhere = tmp_path / "nowhere"
    connect(window, tmp_path, endpoint, {"keys": str(nowhere), "identity": "op1"})
    assert said(window, qtbot, "error") == (
        f"bus.keys {nowhere} holds no site keys (ca.pem is missing); make them with 'optrack "
        "site init --out FOLDER' and copy the folder to this computer."
    )
    window.source.close()
    window.log_panel.list.clear()
    connect(window, tmp_path, endpoint, {})
    sentence = said(window, qtbot, "error")
    assert sentence.startswith("joining a site over the network (bus.mode peer) needs the site")
    assert "optrack site init --out FOLDER --stations NAME" in sentence
    assert "bus.keys: FOLDER" in sentence and sentence.count(". ") == 0


def test_an_insecure_site_is_shown_as_such_in_the_status_bar(qtbot, window, tmp_path, processes):
    endpoint = tracker(processes, tmp_path, {}, "--insecure")
    source = connect(window, tmp_path, endpoint, {"insecure": True})
    qtbot.waitUntil(lambda: "tracker" in source.client.statuses(), timeout=60000)
    assert source.client.statuses()["tracker"]["values"]["insecure"] is True
    warning = window.insecure_warning
    qtbot.waitUntil(lambda: warning.isVisibleTo(window), timeout=5000)
    assert warning.text() == INSECURE_TEXT
    assert "no TLS and no access control" in warning.toolTip()
    assert "optrack site init" in warning.toolTip()
    window.set_source(SiteSource(window))  # no site: no warning
    qtbot.waitUntil(lambda: warning.isHidden(), timeout=5000)
    source.close()
