"""A ``peer`` site across five computers made of network namespaces on this one: the
walk-through of docs/runtime.md, "Several computers", step by step
(:func:`optrack.bench.site.site_bench`, the same as ``optrack bench site``, on the small
venue recording of this folder's conftest).

Runs as root where ``ip netns`` works (CI does); skipped elsewhere with the reason."""

from __future__ import annotations

import subprocess
import sys

import pytest

from optrack.bench.netns import PREFIX, Lab, clean_stale, netns_problem

PROBLEM = netns_problem()
pytestmark = pytest.mark.skipif(
    PROBLEM is not None, reason=f"network namespaces unavailable: {PROBLEM}"
)


def _namespaces() -> set[str]:
    listed = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True).stdout
    return {line.split(" ")[0] for line in listed.splitlines() if line.startswith(PREFIX)}


def _reach(lab: Lab, host: str, address: str) -> str:
    """How a TCP connection from ``host`` to ``address`` port 9 ends."""
    code = (
        "import errno, socket\n"
        "try:\n"
        f"    socket.create_connection(('{address}', 9), timeout=5)\n"
        "    print('connected')\n"
        "except OSError as e:\n"
        "    print('no route' if e.errno == errno.ENETUNREACH else type(e).__name__)\n"
    )
    argv = lab.command(host, [sys.executable, "-c", code])
    return subprocess.run(argv, capture_output=True, text=True, timeout=30).stdout.strip()


def test_a_lab_is_removed_even_when_its_user_fails():
    before = _namespaces()
    with pytest.raises(RuntimeError, match="inside"):
        with Lab(["a", "b"]) as lab:
            assert {lab.netns("a"), lab.netns("b"), lab.switch} <= _namespaces()
            assert _reach(lab, "a", lab.addresses["b"]) == "ConnectionRefusedError"  # b answers
            assert _reach(lab, "a", "192.0.2.1") == "no route"  # nothing leaves the lab
            raise RuntimeError("a failure inside")
    assert _namespaces() == before


def test_what_a_crashed_run_left_is_removed_by_the_next():
    stale = f"{PREFIX}{2**22 + 4321}sw"  # above any pid Linux hands out: that run is gone
    subprocess.run(["ip", "netns", "add", stale], check=True)
    try:
        assert stale in clean_stale()
        assert stale not in _namespaces()
    finally:
        subprocess.run(["ip", "netns", "del", stale], capture_output=True)


def test_peer_site_across_network_namespaces(venue):
    from optrack.bench.site import SiteProtocol, site_bench

    before = _namespaces()
    result = site_bench(venue, SiteProtocol(settle_s=1.0))
    assert _namespaces() == before  # every namespace, veth and the bridge removed
    # tracks went on from the other sensors while d0's cable was out, the tracker named it
    assert result["link_cut_tracks_datagrams"] > 0
    assert result["link_silent_reported_s"] is not None
    assert result["link_rejoin_s"] <= 5.0
    assert result["tracker_recovery_s"] <= 5.0
    assert result["foreign_node_refused"] is True
    assert result["injection_control_seen"] is True
    assert result["injections_refused"] == result["injections_tried"] == 5
    assert result["datagrams"] > 0
    assert result["datagrams_unparseable"] == 0
    # the tracker was restarted once (it was killed); no node crashed
    assert result["restarts"] == {"tracker": 1, "kinect2_0": 0, "kinect2_1": 0, "kinect2_2": 0}
