"""``optrack bench detection --pcl-binary``: PCL's C++ harness and this detector in
alternate rounds on one core. PCL is not in CI: the harness is stood in for by a small
script printing its output format; the real harness runs where it is built."""

from __future__ import annotations

import os
import stat
import statistics
from pathlib import Path

import pytest

from optrack.bench.detection import (
    PCL_BINARY,
    detection_bench,
    parse_pcl_harness,
    pcl_comparison,
)
from optrack.errors import UserError

#: The lines of people_bench's output the bench reads (a real run's, 2026-11-26).
HARNESS_OUTPUT = """\
file: ../shared/data/pcl/five_people.pcd
cloud: 640 x 480 (organized=1), 307200 points, 239075 finite
clusters: 7
people (confidence > -1.50): 5
compute() [full, with HOG]:        n=20 mean=60.776 median=61.075 min=55.461 p90=64.457 max=66.226 sd=3.250 (ms)
vs first call: cluster-count mismatches 0 of 20, max |d conf| 0, max |d centroid| 0 m
stage filter() [VoxelGrid]:        n=20 mean=22.921 median=22.617 min=16.517 p90=29.663 max=33.592 sd=5.685 (ms)
"""


def test_the_harness_output_gives_its_median_and_people():
    assert parse_pcl_harness(HARNESS_OUTPUT) == (61.075, 5)
    with pytest.raises(UserError, match="median"):
        parse_pcl_harness("stage filter() [VoxelGrid]: n=20 median=22.6 (ms)\n")


def _fake_harness(tmp_path: Path, medians: list[float]) -> tuple[Path, Path]:
    """An executable printing the harness's format, the next of ``medians`` each run, and
    logging its arguments, allowed cores and OMP_NUM_THREADS."""
    log = tmp_path / "calls.log"
    script = tmp_path / "people_bench"
    values = " ".join(str(m) for m in medians)
    script.write_text(
        "#!/bin/sh\n"
        f'n=$(cat "{log}" 2>/dev/null | wc -l)\n'
        f"i=0; for v in {values}; do [ $i -eq $n ] && m=$v; i=$((i+1)); done\n"
        "cores=$(grep Cpus_allowed_list /proc/self/status | cut -f2)\n"
        f'echo "$* | $cores | $OMP_NUM_THREADS" >> "{log}"\n'
        "echo 'people (confidence > -1.50): 5'\n"
        'echo "compute() [full, with HOG]:        n=30 mean=1 median=$m min=1 p90=1 max=1 sd=0 (ms)"\n'
    )
    script.chmod(script.stat().st_mode | stat.S_IXUSR)
    return script, log


@pytest.mark.skipif(not hasattr(os, "sched_getaffinity"), reason="pinning needs Linux")
def test_rounds_alternate_on_one_core_and_pair_up(shared_data, tmp_path):
    script, log = _fake_harness(tmp_path, [20.0, 40.0, 30.0])
    before = os.sched_getaffinity(0)
    out = pcl_comparison(script, shared_data, rounds=3, iters=2)
    assert os.sched_getaffinity(0) == before  # pinned only while it measures
    calls = log.read_text().splitlines()
    assert len(calls) == 3
    for call in calls:
        arguments, cores, omp = (part.strip() for part in call.split("|"))
        assert arguments.split()[1:5] == ["--iters", "2", "--mode", "full"]
        assert arguments.split()[0].endswith("five_people.pcd")
        assert arguments.endswith("trainedLinearSVMForPeopleDetectionWithHOG.yaml")
        assert cores.isdigit()  # one core, not a list or a range
        assert omp == "1"
    assert out["pcl_five_people_ms_rounds"] == [20.0, 40.0, 30.0]
    ours = out["five_people_ms_pinned_rounds"]
    assert len(ours) == 3 and all(ms > 0 for ms in ours)
    assert out["pcl_five_people_ms"] == 30.0
    assert out["five_people_ms_pinned"] == statistics.median(ours)
    ratios = [mine / theirs for mine, theirs in zip(ours, [20.0, 40.0, 30.0], strict=True)]
    assert out["five_people_ratio_pcl"] == pytest.approx(statistics.median(ratios))
    assert out["pcl_five_people_count"] == 5
    assert "3 alternate rounds of 2 frames" in out["pcl_comparison"]


def test_without_the_harness_the_figures_are_null_and_say_how_to_build_it(tmp_path):
    out = pcl_comparison(None, tmp_path)
    assert out["pcl_five_people_ms"] is None and out["five_people_ratio_pcl"] is None
    assert out["five_people_ms_pinned"] is None
    assert "cmake -S ../shared/bench/pcl_people -B build/pcl" in out["pcl_comparison"]
    assert pcl_comparison(tmp_path / "missing", tmp_path)["five_people_ratio_pcl"] is None


def test_a_harness_that_is_not_executable_or_fails_is_one_sentence(shared_data, tmp_path):
    not_executable = tmp_path / "people_bench.txt"
    not_executable.write_text("")
    with pytest.raises(UserError, match="not an executable file"):
        detection_bench(not_executable)
    failing = tmp_path / "failing"
    failing.write_text("#!/bin/sh\necho 'cannot read the frame' >&2\nexit 1\n")
    failing.chmod(0o755)
    with pytest.raises(UserError, match="failed .exit 1.: cannot read the frame"):
        pcl_comparison(failing, shared_data, rounds=1, iters=1)


def test_pcls_own_harness_where_it_is_built(shared_data):
    binary = Path(__file__).resolve().parents[2] / PCL_BINARY
    if not binary.is_file():
        pytest.skip(f"PCL's harness needs libpcl-dev and a build: {binary} is not built")
    out = pcl_comparison(binary, shared_data, rounds=1, iters=3)
    assert out["pcl_five_people_count"] == 5
    assert out["pcl_five_people_ms"] > 0 and out["five_people_ratio_pcl"] > 0
