"""Key expressions of a site, and the Zenoh configuration each bus mode makes."""

from __future__ import annotations

import json

import pytest

from optrack.net.config import BUS_PARAMS, BusConfigError, site_identity, zenoh_config
from optrack.net.keys import BusNameError, SiteKeys
from optrack.net.security import LOCAL_IDENTITY


def get(config, key: str):
    return json.loads(config.get_json(key))


def test_site_keys_follow_the_design():
    keys = SiteKeys("lab")
    assert keys.detections("cam0") == "optrack/lab/detections/cam0"
    assert keys.detections() == "optrack/lab/detections/*"
    assert keys.tracks == "optrack/lab/tracks"
    assert keys.calibration == "optrack/lab/calibration"
    assert keys.params("tracker") == "optrack/lab/params/tracker"
    assert keys.status("cam0") == "optrack/lab/status/cam0"
    assert keys.preview("cam0") == "optrack/lab/preview/cam0"
    assert keys.clock == "optrack/lab/clock"
    assert SiteKeys.last_chunk(keys.detections("cam0")) == "cam0"


@pytest.mark.parametrize("name", ["", "a/b", "cam*", "x$y", "-lead", "a" * 65, "sp ace"])
def test_names_that_cannot_be_a_key_chunk_are_refused(name):
    with pytest.raises(BusNameError, match="cannot be used on the bus"):
        SiteKeys("lab").detections(name)


def test_site_name_is_checked():
    with pytest.raises(BusNameError):
        SiteKeys("my site")


def test_local_hub_listens_on_loopback_only_and_does_not_scout():
    config = zenoh_config(BUS_PARAMS.create({"local_port": 17111}), host=True)
    assert get(config, "mode") == "router"
    assert get(config, "listen/endpoints") == ["tls/127.0.0.1:17111"]  # mutual TLS
    assert get(config, "connect/endpoints") == []
    assert get(config, "scouting/multicast/enabled") is False
    assert get(config, "scouting/gossip/enabled") is False


def test_local_node_is_a_client_of_the_loopback_hub():
    config = zenoh_config(BUS_PARAMS.create({"local_port": 17111}))
    assert get(config, "mode") == "client"
    assert get(config, "connect/endpoints") == ["tls/127.0.0.1:17111"]
    assert get(config, "listen/endpoints") == []
    assert get(config, "scouting/multicast/enabled") is False


def test_local_mode_refuses_an_endpoint_off_this_computer():
    with pytest.raises(BusConfigError, match="bus.mode peer"):
        zenoh_config(BUS_PARAMS.create({"connect": "tcp/192.168.1.10:7447"}))


def test_peer_mode_takes_endpoints_and_scouting_from_the_config():
    config = zenoh_config(
        BUS_PARAMS.create(
            {
                "mode": "peer",
                "insecure": True,
                "connect": "tcp/192.168.1.10:7447, tcp/192.168.1.11:7447",
                "listen": "tcp/0.0.0.0:7447",
                "multicast_scouting": False,
            }
        )
    )
    assert get(config, "mode") == "peer"
    assert get(config, "connect/endpoints") == ["tcp/192.168.1.10:7447", "tcp/192.168.1.11:7447"]
    assert get(config, "listen/endpoints") == ["tcp/0.0.0.0:7447"]
    assert get(config, "scouting/multicast/enabled") is False
    assert get(config, "scouting/gossip/enabled") is True


def test_peer_mode_scouts_by_default():
    config = zenoh_config(BUS_PARAMS.create({"mode": "peer", "insecure": True}))
    assert get(config, "scouting/multicast/enabled") is True


def test_client_mode_needs_somewhere_to_connect():
    with pytest.raises(BusConfigError, match="bus.connect"):
        zenoh_config(BUS_PARAMS.create({"mode": "client", "multicast_scouting": False}))


def test_endpoint_without_protocol_is_refused():
    with pytest.raises(BusConfigError, match="tcp/HOST:PORT"):
        zenoh_config(BUS_PARAMS.create({"mode": "peer", "connect": "192.168.1.10:7447"}))


def test_zenoh_config_file_is_used_as_it_is(tmp_path):
    path = tmp_path / "zenoh.json5"
    path.write_text('{ mode: "peer", connect: { endpoints: ["tcp/10.1.2.3:7447"] } }')
    config = zenoh_config(BUS_PARAMS.create({"zenoh_config": str(path)}))
    assert get(config, "connect/endpoints") == ["tcp/10.1.2.3:7447"]


def test_missing_zenoh_config_file_says_so(tmp_path):
    with pytest.raises(BusConfigError, match="does not exist"):
        zenoh_config(BUS_PARAMS.create({"zenoh_config": str(tmp_path / "nope.json5")}))


def test_an_insecure_client_of_a_hub_on_this_computer_joins_as_plain_tcp(tmp_path, monkeypatch):
    """The nodes of an insecure peer site join its hub over loopback without TLS (the hub
    listens on plain tcp); without bus.insecure they present this user's local keys, and a
    local site ignores bus.insecure."""
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path))
    loopback = {"mode": "client", "connect": "tcp/127.0.0.1:7447", "multicast_scouting": False}
    config = zenoh_config(BUS_PARAMS.create({**loopback, "insecure": True}))
    assert get(config, "connect/endpoints") == ["tcp/127.0.0.1:7447"]
    assert site_identity(BUS_PARAMS.create({**loopback, "insecure": True})) is None
    assert site_identity(BUS_PARAMS.create(loopback))[1] == LOCAL_IDENTITY
    assert get(zenoh_config(BUS_PARAMS.create(loopback)), "connect/endpoints") == [
        "tls/127.0.0.1:7447"
    ]
    assert site_identity(BUS_PARAMS.create({"insecure": True}))[1] == LOCAL_IDENTITY
