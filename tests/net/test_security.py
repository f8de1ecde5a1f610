"""A site's identity: keys made by 'optrack site init', mutual TLS and access control on
real Zenoh sessions (loopback)."""

from __future__ import annotations

import json
import stat
import threading
import time

import pytest
from cryptography import x509
from cryptography.hazmat.primitives import serialization
from cryptography.x509.oid import NameOID

from optrack.cli import main
from optrack.net.bus import Bus, BusError
from optrack.net.config import BUS_PARAMS, BusConfigError
from optrack.net.messages import (
    CalibrationMessage,
    CommandReply,
    CommandRequest,
    DetectionsMessage,
    ParamsMessage,
    encode,
)
from optrack.net.security import (
    KeysError,
    SiteIdentities,
    init_site,
    local_keys,
    verified_roles,
)
from optrack.runtime.node import CommandError, send_command
from optrack.types import DetectionBatch, NetworkCalibration
from tests.net.conftest import free_port

NODES = ["tracker", "kinect2_0"]


@pytest.fixture(scope="module")
def site_keys(tmp_path_factory):
    folder = tmp_path_factory.mktemp("keys") / "lab"
    init_site(folder, NODES, ["op1"], site="lab")
    return folder


@pytest.fixture(scope="module")
def foreign_keys(tmp_path_factory):
    """Another site's keys, with the very same names."""
    folder = tmp_path_factory.mktemp("keys") / "elsewhere"
    init_site(folder, NODES, ["op1"], site="elsewhere")
    return folder


def wait_until(condition, timeout=10.0):
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.02)


def test_site_init_makes_an_authority_and_certificates_it_signed(tmp_path, capsys):
    folder = tmp_path / "keys"
    code = main(
        ["site", "init", "--out", str(folder), "--nodes", "tracker,kinect2_0,site"]
        + ["--stations", "op1", "--json"]
    )
    assert code == 0
    report = json.loads(capsys.readouterr().out)
    assert sorted(report["made"]) == ["kinect2_0", "op1", "site", "tracker"]
    assert report["roles"] == {
        "kinect2_0": "detector",
        "op1": "station",
        "site": "launcher",
        "tracker": "tracker",
    }
    ca = x509.load_pem_x509_certificate((folder / "ca.pem").read_bytes())
    assert ca.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
    for name, role in report["roles"].items():
        cert = x509.load_pem_x509_certificate((folder / f"{name}.pem").read_bytes())
        cert.verify_directly_issued_by(ca)  # raises when the signature does not hold
        assert cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value == name
        unit = cert.subject.get_attributes_for_oid(NameOID.ORGANIZATIONAL_UNIT_NAME)[0].value
        assert unit == role
        assert stat.S_IMODE((folder / f"{name}-key.pem").stat().st_mode) == 0o600
    assert stat.S_IMODE(folder.stat().st_mode) == 0o700
    assert stat.S_IMODE((folder / "ca-key.pem").stat().st_mode) == 0o600
    # Run again: one more identity, nothing made anew.
    before = (folder / "tracker.pem").read_bytes()
    assert main(["site", "init", "--out", str(folder), "--nodes", "kinect2_1"]) == 0
    assert (folder / "tracker.pem").read_bytes() == before
    assert (folder / "ca.pem").read_bytes() == ca.public_bytes(serialization.Encoding.PEM)
    assert SiteIdentities(folder).roles["kinect2_1"] == "detector"
    assert verified_roles(folder) == SiteIdentities(folder).roles


def test_a_certificate_of_another_authority_is_never_listed(site_keys, foreign_keys, tmp_path):
    copy = tmp_path / "copy"
    copy.mkdir()
    for path in site_keys.iterdir():
        (copy / path.name).write_bytes(path.read_bytes())
    (copy / "spy.pem").write_bytes((foreign_keys / "op1.pem").read_bytes())
    (copy / "spy-key.pem").write_bytes((foreign_keys / "op1-key.pem").read_bytes())
    assert "spy" not in verified_roles(copy)
    assert init_site(copy, ["kinect2_5"]) == ["kinect2_5"]  # the list is made anew
    assert set(SiteIdentities(copy).roles) == {"tracker", "kinect2_0", "kinect2_5", "op1"}


def test_an_identity_without_its_authority_key_or_a_missing_name_is_one_sentence(
    site_keys, tmp_path
):
    copy = tmp_path / "copy"
    copy.mkdir()
    for path in site_keys.iterdir():
        if path.name != "ca-key.pem":
            (copy / path.name).write_bytes(path.read_bytes())
    with pytest.raises(KeysError, match="authority's key"):
        init_site(copy, ["kinect2_9"])
    with pytest.raises(KeysError, match="hold no identity 'nobody'"):
        SiteIdentities(copy).require("nobody")
    with pytest.raises(KeysError, match="optrack site init"):
        SiteIdentities(tmp_path / "empty")


def test_local_keys_are_made_once_and_kept_for_this_user_only(tmp_path):
    folder = local_keys(tmp_path)
    first = (folder / "local.pem").read_bytes()
    assert local_keys(tmp_path) == folder
    assert (folder / "local.pem").read_bytes() == first  # cached, not made again
    assert stat.S_IMODE(folder.stat().st_mode) == 0o700
    assert stat.S_IMODE((folder / "local-key.pem").stat().st_mode) == 0o600
    assert not (folder / "ca-key.pem").exists()  # nothing is ever added to them


def params(keys, port, identity="", **more):
    return BUS_PARAMS.create(
        {
            "local_port": port or 7447,  # peers: unused
            "keys": str(keys),
            "identity": identity,
            "connect_timeout_s": 2.0,
            **more,
        }
    )


def batch(sensor: str) -> DetectionBatch:
    return DetectionBatch(sensor_id=sensor, stamp=time.time(), frame_id="world", detections=[])


def test_peers_with_the_sites_keys_exchange_messages_over_tls(site_keys):
    port = free_port()
    links = {"mode": "peer", "multicast_scouting": False, "gossip": False}
    tracker = Bus("lab", "tracker", params(site_keys, 0, listen=f"tcp/127.0.0.1:{port}", **links))
    got: list[str] = []
    tracker.subscribe(tracker.keys.detections(), DetectionsMessage, lambda m, k: got.append(k))
    camera = Bus("lab", "kinect2_0", params(site_keys, 0, connect=f"tcp/127.0.0.1:{port}", **links))
    try:
        assert not tracker.insecure and not camera.insecure
        assert camera.session.info.peers_zid()  # the TLS link is up
        key = camera.keys.detections("kinect2_0")
        deadline = time.monotonic() + 10
        while not got and time.monotonic() < deadline:
            camera.publish(key, DetectionsMessage(batch=batch("kinect2_0")))
            time.sleep(0.05)
        assert got and got[0] == key
    finally:
        camera.close()
        tracker.close()


def test_a_node_with_another_sites_keys_cannot_connect(site_keys, foreign_keys):
    port = free_port()
    hub = Bus("lab", "tracker", params(site_keys, port), host=True)
    try:
        member = Bus("lab", "op1", params(site_keys, port))
        member.close()
        with pytest.raises(BusError, match="cannot reach the local site's hub"):
            Bus("lab", "op1", params(foreign_keys, port, connect_timeout_s=0.5))
    finally:
        hub.close()


def test_a_foreign_peer_never_joins_and_its_puts_never_arrive(site_keys, foreign_keys):
    port = free_port()
    links = {"mode": "peer", "multicast_scouting": False, "gossip": False}
    tracker = Bus("lab", "tracker", params(site_keys, 0, listen=f"tcp/127.0.0.1:{port}", **links))
    got: list[str] = []
    tracker.subscribe(tracker.keys.detections(), DetectionsMessage, lambda m, k: got.append(k))
    connect = f"tcp/127.0.0.1:{port}"
    intruder = Bus("lab", "kinect2_0", params(foreign_keys, 0, connect=connect, **links))
    camera = Bus("lab", "kinect2_0", params(site_keys, 0, connect=connect, **links))
    try:
        intruder.put_raw(
            intruder.keys.detections("kinect2_0"),
            encode(DetectionsMessage(batch=batch("kinect2_0"), sender="intruder")),
        )
        wait_until(lambda: camera.session.info.peers_zid())
        deadline = time.monotonic() + 10
        while not got and time.monotonic() < deadline:
            camera.publish(
                camera.keys.detections("kinect2_0"), DetectionsMessage(batch=batch("kinect2_0"))
            )
            time.sleep(0.05)
        assert got  # the site works
        assert not intruder.session.info.peers_zid()  # the intruder has no link at all
        assert str(intruder.session.zid()) not in {str(z) for z in tracker.session.info.peers_zid()}
    finally:
        for bus in (intruder, camera, tracker):
            bus.close()


def test_only_operator_stations_put_parameters_calibrations_and_commands(site_keys):
    port = free_port()
    hub = Bus("lab", "tracker", params(site_keys, port), host=True)
    station = Bus("lab", "op1", params(site_keys, port))
    camera = Bus("lab", "kinect2_0", params(site_keys, port))
    seen: dict[str, list[str]] = {"params": [], "calibration": [], "detections": [], "commands": []}
    lock = threading.Lock()

    def note(kind):
        def add(message, key):
            with lock:
                seen[kind].append(message.sender)

        return add

    hub.subscribe(hub.keys.params("tracker"), ParamsMessage, note("params"))
    hub.subscribe(hub.keys.calibration, CalibrationMessage, note("calibration"))
    hub.subscribe(hub.keys.detections(), DetectionsMessage, note("detections"))

    def answer(request: CommandRequest):
        with lock:
            seen["commands"].append(request.sender)
        return CommandReply(node="tracker", action=request.action, ok=True)

    hub.serve(hub.keys.command("tracker"), CommandRequest, answer)
    try:
        # The detector node's identity: parameters, a calibration, detections of another
        # sensor, then its own sensor's detections (same link, in order).
        def params_message():
            return ParamsMessage(updates={"tracking": {"max_speed": 9.0}})

        camera.publish(camera.keys.params("tracker"), params_message(), realtime=False)
        camera.publish(
            camera.keys.calibration,
            CalibrationMessage(calibration=NetworkCalibration()),
            realtime=False,
        )
        camera.publish(
            camera.keys.detections("kinect2_1"),
            DetectionsMessage(batch=batch("kinect2_1")),
            realtime=False,
        )
        with pytest.raises(CommandError, match="did not answer"):
            send_command(camera, "tracker", "stop", timeout=0.5)
        deadline = time.monotonic() + 10
        while not seen["detections"] and time.monotonic() < deadline:
            camera.publish(
                camera.keys.detections("kinect2_0"),
                DetectionsMessage(batch=batch("kinect2_0")),
                realtime=False,
            )
            time.sleep(0.05)
        # The operator station: the same parameters and command arrive.
        station.publish(station.keys.params("tracker"), params_message(), realtime=False)
        assert send_command(station, "tracker", "stop", timeout=5.0) == {}
        wait_until(lambda: seen["params"])
        with lock:
            assert seen["params"] == ["op1"]
            assert seen["calibration"] == []
            assert set(seen["detections"]) == {"kinect2_0"}
            assert seen["commands"] == ["op1"]
    finally:
        for bus in (camera, station, hub):
            bus.close()


def test_peer_mode_without_keys_refuses_unless_insecure():
    with pytest.raises(BusConfigError, match="--insecure"):
        Bus("lab", "tracker", BUS_PARAMS.create({"mode": "peer", "multicast_scouting": False}))
    bus = Bus(
        "lab",
        "tracker",
        BUS_PARAMS.create(
            {
                "mode": "peer",
                "multicast_scouting": False,
                "insecure": True,
                "listen": f"tcp/127.0.0.1:{free_port()}",
            }
        ),
    )
    try:
        assert bus.insecure
    finally:
        bus.close()
