"""The skeleton's automatic thread count (threads 0): the cores that no other process keeps
busy, from the machine's real CPU times (Linux's /proc/stat) and from CPU-time files
written here, with a real process keeping a core busy."""

from __future__ import annotations

import logging
import os
import subprocess
import sys
import time

import numba
import pytest

from optrack.skeleton.cores import SpareCores, _usable_cores
from optrack.skeleton.likelihood import set_threads
from optrack.skeleton.params import SKELETON_PARAMS

TICK = os.sysconf("SC_CLK_TCK")


def _stat(path, busy_s: float) -> None:
    """A /proc/stat whose machine has spent ``busy_s`` seconds busy (user time)."""
    user = round(busy_s * TICK)
    path.write_text(f"cpu  {user} 0 0 1000000 0 0 0 0 0 0\ncpu0 {user} 0 0 1000000 0 0 0 0 0 0\n")


def test_the_default_is_auto():
    assert SKELETON_PARAMS.create().threads == 0


def test_a_core_the_others_keep_busy_is_not_spare(tmp_path):
    stat = tmp_path / "stat"
    cores = SpareCores(period=0.2, stat=str(stat))
    _stat(stat, 100.0)
    assert cores() == 1  # the first sample: nothing to compare yet, so one thread
    time.sleep(0.3)
    # Over the 0.3 s the machine was busy for 0.3 s, none of it this process's: the
    # others kept one core busy.
    _stat(stat, 100.3)
    assert cores() == max(1, _usable_cores() - 1)
    assert cores.others == pytest.approx(1.0, abs=0.15)
    time.sleep(0.3)
    _stat(stat, 100.3)  # then idle: every usable core is spare
    assert cores() == _usable_cores()
    assert cores.others < 0.1


def test_samples_are_kept_for_the_period(tmp_path):
    stat = tmp_path / "stat"
    cores = SpareCores(period=60.0, stat=str(stat))
    _stat(stat, 5.0)
    cores()
    _stat(stat, 500.0)  # within the period the file is not read again
    assert cores() == 1 and cores.others == 0.0


def test_without_the_cpu_times_one_thread(tmp_path, caplog):
    missing = SpareCores(period=0.0, stat=str(tmp_path / "absent"))
    with caplog.at_level(logging.INFO, logger="optrack.skeleton"):
        assert missing() == 1 and missing() == 1
    said = [
        r.getMessage() for r in caplog.records if "could not read the CPU times" in r.getMessage()
    ]
    assert len(said) == 1 and "absent" in said[0] and "skeleton.threads" in said[0]
    odd = tmp_path / "odd"
    odd.write_text("intr 1 2 3\n")
    assert SpareCores(period=0.0, stat=str(odd))() == 1


@pytest.mark.skipif(not os.path.exists("/proc/stat"), reason="needs Linux's /proc/stat")
@pytest.mark.skipif(_usable_cores() < 2, reason="needs two cores")
def test_a_busy_process_takes_the_second_thread_away():
    """On this machine's real CPU times: with another process spinning on a core, auto
    gives one thread fewer than with it stopped; set_threads(0) follows it."""
    cores = SpareCores(period=0.5)
    spinner = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        cores()
        time.sleep(1.0)
        busy = cores()
        others = cores.others
    finally:
        spinner.kill()
        spinner.wait()
    assert others >= 0.7, f"the spinning process was seen as {others:.2f} of a core"
    assert busy <= _usable_cores() - 1
    time.sleep(1.0)
    cores()
    time.sleep(1.0)
    assert cores() > busy or cores.others >= 0.7  # freed, unless something else took it
    set_threads(0)
    assert 1 <= numba.get_num_threads() <= _usable_cores()
    set_threads(1)
    assert numba.get_num_threads() == 1
