"""optrack bench install's watcher: the time to a site's first UDP datagram with tracks
(the package test and the bench run it on /usr/bin/optrack; here on small senders)."""

from __future__ import annotations

import sys

import pytest

from optrack.bench.install import clean_env, watch_tracks

# Sends what `optrack run --udp HOST:PORT` would: first a datagram without tracks, then
# one with a track, then exits with the status it is given.
SENDER = """
import json, socket, sys, time
host, port = sys.argv[sys.argv.index("--udp") + 1].split(":")
with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
    for tracks in ([], [{"id": 1, "x": 0.0, "y": 0.0}]):
        time.sleep(0.3)
        sock.sendto(json.dumps({"tracks": tracks}).encode(), (host, int(port)))
sys.exit(int(sys.argv[1]))
"""


def test_the_first_datagram_with_a_track_is_timed_and_the_run_waited_for() -> None:
    figures = watch_tracks([sys.executable, "-c", SENDER, "0"], clean_env(), 30, to_end=True)
    assert 0.5 <= figures["first_tracks_s"] <= figures["run_s"]


def test_a_run_that_fails_after_its_tracks_fails_the_watch() -> None:
    with pytest.raises(RuntimeError, match="exit 3"):
        watch_tracks([sys.executable, "-c", SENDER, "3"], clean_env(), 30, to_end=True)


def test_a_run_without_tracks_fails_with_its_stderr() -> None:
    command = [sys.executable, "-c", "import sys; sys.exit('no camera here')"]
    with pytest.raises(RuntimeError, match="no camera here"):
        watch_tracks(command, clean_env(), 30)


def test_tracks_may_be_optional_but_the_exit_status_is_not() -> None:
    quiet = [sys.executable, "-c", "pass"]
    figures = watch_tracks(quiet, clean_env(), 30, to_end=True, need_tracks=False)
    assert figures["first_tracks_s"] is None and figures["run_s"] < 30
    failing = [sys.executable, "-c", "import sys; sys.exit(2)"]
    with pytest.raises(RuntimeError, match="exit 2"):
        watch_tracks(failing, clean_env(), 30, to_end=True, need_tracks=False)
