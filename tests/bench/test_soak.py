"""``optrack bench soak`` for a few seconds: the site runs, sends datagrams, restarts nothing,
and every figure is there (the 10-minute soak is for the command)."""

from __future__ import annotations

import os

import pytest

from optrack.bench.soak import rss_kb, soak_bench
from optrack.errors import UserError


def test_rss_of_this_process_and_of_none():
    assert rss_kb(os.getpid()) > 1000
    assert rss_kb(2**22 + 12345) is None


def test_minutes_must_be_positive():
    with pytest.raises(UserError, match="--minutes"):
        soak_bench(0.0)


def test_a_short_soak_of_the_live_venue():
    result = soak_bench(0.25, live=True, sample_s=2.0)
    for key in ("rss_growth_pct", "restarts", "dropped_pct", "datagrams", "rss_mb"):
        assert key in result
    assert result["datagrams"] > 0
    assert result["unparseable"] == 0
    assert result["restarts"] == 0
    names = {name.split(":")[0] for name in result["rss_mb"]}
    assert {"tracker", "kinect2_0", "kinect2_1", "kinect2_2", "launcher"} <= names
    assert result["dropped_pct"] is not None and 0.0 <= result["dropped_pct"] <= 100.0
