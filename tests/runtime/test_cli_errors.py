"""What `optrack node detect`, `optrack node track` and `optrack run` say when the user
got something wrong: exit status 1 and one sentence naming the thing."""

from __future__ import annotations

import pytest
import yaml

from optrack.cli import main
from optrack.net.bus import Bus

from .conftest import free_port


def config(tmp_path, **stages) -> str:
    path = tmp_path / "site.yaml"
    path.write_text(yaml.safe_dump(stages))
    return str(path)


def run(capsys, *argv: str) -> tuple[int, str]:
    code = main(list(argv))
    return code, capsys.readouterr().err


@pytest.mark.parametrize(
    ("uri", "sentence"),
    [
        ("bogus://x", "unknown scheme 'bogus'"),
        ("file://{venue}?realtime=false#kinect2_0", "plays recordings in real time"),
        ("file://{venue}?fast=yes#kinect2_0", "sets 'fast'"),
        ("file://{venue}", "name one"),
        ("file:///no/such/recording#a", "does not exist"),
    ],
)
def test_detector_node_refuses_a_sensor_it_cannot_use(capsys, venue, uri, sentence):
    code, err = run(capsys, "node", "detect", "--sensor", uri.format(venue=venue), "--site", "x")
    assert code == 1
    assert sentence in err
    assert "Traceback" not in err


def test_site_name_that_cannot_be_a_key_is_refused(capsys, venue):
    code, err = run(
        capsys, "node", "detect", "--sensor", f"file://{venue}#kinect2_0", "--site", "my site"
    )
    assert code == 1
    assert "site name 'my site' cannot be used on the bus" in err


def test_detector_node_without_a_site_to_join_says_what_to_start(capsys, venue, tmp_path):
    path = config(tmp_path, bus={"local_port": free_port(), "connect_timeout_s": 0.3})
    code, err = run(
        capsys,
        "node",
        "detect",
        "--sensor",
        f"file://{venue}#kinect2_0",
        "--site",
        "x",
        "--config",
        path,
    )
    assert code == 1
    assert "start the tracker node first" in err


def test_tracker_node_on_a_port_another_site_holds_says_so(capsys, tmp_path, bus_params):
    other = Bus("other", "tracker", bus_params, host=True)
    try:
        path = config(tmp_path, bus={"local_port": int(bus_params.local_port)})
        code, err = run(capsys, "node", "track", "--site", "x", "--config", path)
    finally:
        other.close()
    assert code == 1
    assert "another site is probably running there" in err


def test_run_refuses_a_duration_that_is_not_positive(capsys):
    code, err = run(capsys, "run", "--headless", "--seconds", "0")
    assert code == 1
    assert "--seconds must be > 0" in err


def test_run_refuses_two_sensors_with_the_same_name(capsys, venue, tmp_path):
    uri = f"file://{venue}?loop=true#kinect2_0"
    path = config(
        tmp_path,
        bus={"local_port": free_port()},
        site={"sensors": f"{uri},{uri}", "report_s": 0.0},
        node={"state_dir": str(tmp_path / "state")},
    )
    code, err = run(capsys, "run", "--headless", "--config", path)
    assert code == 1
    assert "both named 'kinect2_0'" in err


def test_a_config_file_with_a_bad_value_is_refused_before_anything_starts(capsys, tmp_path):
    path = config(tmp_path, outputs={"heartbeat_s": -1})
    code, err = run(capsys, "node", "track", "--site", "x", "--config", path)
    assert code == 1
    assert "outputs.heartbeat_s must be between" in err


@pytest.mark.parametrize(
    ("udp", "sentence"),
    [
        ("127.0.0.1:abc", "--udp destination '127.0.0.1:abc' has a bad port 'abc'"),
        ("127.0.0.1:99999", "--udp destination '127.0.0.1:99999' has a bad port '99999'"),
        ("127.0.0.1:5000,:0", "--udp destination ':0' has a bad port '0'"),
        ("nosuch.invalid:5000", "the host 'nosuch.invalid' is unknown"),
    ],
)
def test_run_refuses_a_udp_destination_where_it_is_parsed(capsys, tmp_path, udp, sentence):
    """``--udp 127.0.0.1:abc`` once printed the destination, left the tracker node
    restarting in a loop, sent nothing and exited 0."""
    path = config(tmp_path, bus={"local_port": free_port()})
    code, err = run(capsys, "run", "--headless", "--seconds", "1", "--udp", udp, "--config", path)
    assert code == 1
    assert sentence in err
    assert ("unknown" in sentence) != ("a port between 1 and 65535" in err)
    assert "Traceback" not in err and err.count("\n") == 1
