"""Outputs, Log and the no-site source: what the operator asks for, and what is reported."""

import logging

from PySide6.QtCore import Qt

from app.source import NO_SITE, SiteSource
from app.widgets.log_panel import LogPanel, QtLogHandler
from app.widgets.outputs_panel import OutputsPanel, check_address


def test_outputs_table_shows_what_the_site_reports(qtbot):
    panel = OutputsPanel()
    qtbot.addWidget(panel)
    panel.set_status(
        "outputs",
        {
            "role": "outputs",
            "destinations": [
                {
                    "kind": "udp",
                    "address": "127.0.0.1:21234",
                    "enabled": True,
                    "packets_per_s": 30.04,
                },
                {
                    "kind": "websocket",
                    "address": "0.0.0.0:8765",
                    "enabled": False,
                    "error": "address 0.0.0.0:8765 is in use",
                },
            ],
        },
    )
    rows = [
        [panel.table.item(r, c).text() for c in range(1, 5)] for r in range(panel.table.rowCount())
    ]
    assert rows == [
        ["UDP JSON", "127.0.0.1:21234", "30.0", ""],
        ["WebSocket", "0.0.0.0:8765", "", "address 0.0.0.0:8765 is in use"],
    ]
    assert panel.table.item(1, 2).toolTip() == "address 0.0.0.0:8765 is in use"
    assert panel.table.item(0, 0).checkState() == Qt.CheckState.Checked
    assert panel.table.item(1, 0).checkState() == Qt.CheckState.Unchecked


def test_other_nodes_statuses_leave_the_outputs_list_alone(qtbot):
    """Every status message carries a destinations list (empty but for outputs nodes):
    a tracker's or detector's status right after the outputs' must not empty the table."""
    panel = OutputsPanel()
    qtbot.addWidget(panel)
    udp = {"kind": "udp", "address": "127.0.0.1:21234", "enabled": True}
    osc = {"kind": "osc", "address": "127.0.0.1:21235", "enabled": True}
    panel.set_status("outputs", {"role": "outputs", "destinations": [udp]})
    panel.set_status("tracker", {"role": "tracker", "destinations": []})
    panel.set_status("kinect2_0", {"role": "detector", "destinations": []})
    assert [d["address"] for d in panel.destinations] == ["127.0.0.1:21234"]
    assert panel.table.rowCount() == 1
    panel.set_status("outputs-lab", {"role": "outputs", "destinations": [osc]})
    assert [d["kind"] for d in panel.destinations] == ["udp", "osc"]
    panel.set_status("outputs", {"role": "outputs", "destinations": []})
    assert [d["kind"] for d in panel.destinations] == ["osc"]


def test_outputs_send_add_remove_and_enable_requests(qtbot):
    panel = OutputsPanel()
    qtbot.addWidget(panel)
    panel.set_connected(True)
    panel.kind.setCurrentIndex(panel.kind.findData("osc"))
    assert panel.address.text() == "127.0.0.1:21235"  # the default address follows the kind
    panel.address.setText("192.168.1.20:7000")
    with qtbot.waitSignal(panel.add_requested) as added:
        panel.add_button.click()
    assert added.args == ["osc", "192.168.1.20:7000"]
    panel.set_destinations([{"kind": "osc", "address": "192.168.1.20:7000", "enabled": True}])
    with qtbot.waitSignal(panel.enable_requested) as enabled:
        panel.table.item(0, 0).setCheckState(Qt.CheckState.Unchecked)
    assert enabled.args == ["osc", "192.168.1.20:7000", False]
    panel.table.selectRow(0)
    with qtbot.waitSignal(panel.remove_requested) as removed:
        panel.remove_button.click()
    assert removed.args == ["osc", "192.168.1.20:7000"]


def test_outputs_refuse_a_bad_address_with_optracks_sentence(qtbot):
    panel = OutputsPanel()
    qtbot.addWidget(panel)
    panel.set_connected(True)
    panel.address.setText("127.0.0.1:70000")
    with qtbot.assertNotEmitted(panel.add_requested):
        panel.add_button.click()
    assert panel.message.text() == (
        "UDP JSON address '127.0.0.1:70000' has a bad port '70000'; write HOST:PORT with a "
        "port between 1 and 65535."
    )
    assert check_address("websocket", "0.0.0.0:0") is None  # a server may take any free port
    assert check_address("osc", "[::1]:9000") is None


def test_outputs_without_a_site_cannot_be_added(qtbot):
    panel = OutputsPanel()
    qtbot.addWidget(panel)
    assert not panel.add_button.isEnabled()
    assert panel.message.text().startswith(NO_SITE)


def test_no_site_answers_every_request_with_a_sentence(qtbot):
    source = SiteSource()
    assert source.describe() == NO_SITE and not source.connected
    with qtbot.waitSignal(source.log) as said:
        source.set_params("detection", {"voxel_size": 0.08})
    assert said.args == ["warning", f"{NO_SITE}: detection.voxel_size was not sent to any node."]
    with qtbot.waitSignal(source.log) as said:
        source.add_output("udp", "127.0.0.1:21234")
    assert said.args[1] == f"{NO_SITE}: the udp output 127.0.0.1:21234 was not started."


def test_log_keeps_the_newest_sentences_with_their_level(qtbot):
    panel = LogPanel(max_lines=3)
    qtbot.addWidget(panel)
    for k in range(5):
        panel.append("info", f"message {k}")
    panel.append("error", "sensor 'door' was unplugged; plug it back in.")
    lines = panel.lines()
    assert len(lines) == 3
    assert lines[-1].endswith("Error: sensor 'door' was unplugged; plug it back in.")
    assert lines[0].endswith("message 3")


def test_python_warnings_reach_the_log_from_any_thread(qtbot):
    import threading

    panel = LogPanel()
    qtbot.addWidget(panel)
    handler = QtLogHandler()
    handler.message.connect(panel.append)
    logger = logging.getLogger("optrack.test_gui_log")
    logger.addHandler(handler)
    try:
        worker = threading.Thread(
            target=lambda: logger.warning("calibration file %s is old", "a.yaml")
        )
        worker.start()
        worker.join()
        logger.info("not shown: below the handler's level")
        qtbot.waitUntil(lambda: len(panel.lines()) == 1)
    finally:
        logger.removeHandler(handler)
    assert panel.lines()[0].endswith("Warning: calibration file a.yaml is old")


def test_the_default_output_with_no_listener_says_so_once_in_grey(qtbot):
    """A UDP destination nobody listens at (the default 127.0.0.1:21234 on a fresh
    machine) is a state, not a fault: 'no receiver on ... yet', in grey, explained."""
    import socket
    import time

    from app.widgets.outputs_panel import NO_RECEIVER_TIP
    from optrack.outputs.udp import Destination

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]  # closed again below: nothing listens there
    destination = Destination("udp", "127.0.0.1", port)
    try:
        for _ in range(10):
            destination.send(b"{}")
            time.sleep(0.01)
        status = destination.status()
    finally:
        destination.close()
    assert status.errors >= 1
    panel = OutputsPanel()
    qtbot.addWidget(panel)
    reported = {"kind": "udp", "address": status.address, "sent": status.sent}
    panel.set_status(
        "outputs", {"role": "outputs", "destinations": [{**reported, "error": status.last_error}]}
    )
    problem = panel.table.item(0, 4)
    assert problem.text() == f"no receiver on 127.0.0.1:{port} yet"
    assert problem.foreground().color().red() < 150  # grey, not the red of a fault
    assert problem.toolTip().startswith(NO_RECEIVER_TIP)
    assert "errors" not in problem.text()
