"""Timing of the skeleton's hot loop and filter step on synthetic clouds (docs/skeleton.md).

Run: ``.venv/bin/python -m tests.skeleton.measure [THREADS]`` (default 1, the
parameter ``threads``). Prints, for 300 and 600 points, the wall and CPU time of one
full-body likelihood of 2000 poses, and of one filter step with the default parameters.
The synthetic-cloud timings of docs/skeleton.md come from it; ``optrack bench skeleton``
measures the whole stage on real motion.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from optrack.skeleton.filter import SkeletonFilter
from optrack.skeleton.likelihood import log_likelihood
from optrack.skeleton.model import PARTS, BodyShape, D, forward_kinematics, part_geometry
from optrack.skeleton.params import SKELETON_PARAMS
from tests.skeleton.clouds import seen_cloud
from tests.skeleton.test_filter import _pose


def _timed(call, repeats: int) -> tuple[list[float], list[float]]:
    wall, cpu = [], []
    for _ in range(repeats):
        t, p = time.perf_counter(), time.process_time()
        call()
        wall.append(time.perf_counter() - t)
        cpu.append(time.process_time() - p)
    return wall, cpu


def main(threads: int) -> None:
    shape = BodyShape.from_height(1.75)
    truth = _pose(shape)
    rng = np.random.default_rng(0)
    joints = forward_kinematics(truth, shape)[0][:16]
    print(f"threads: {threads}")
    geometry = part_geometry(
        *forward_kinematics(truth + rng.normal(0, 0.05, (2000, D)), shape), shape
    )
    expected = np.full((len(PARTS), 2), 3.0)
    for n in (300, 600):
        points = seen_cloud(truth, shape, rng, points=n)
        log_likelihood(points, geometry, expected, 0.15, 0.6, 0.5, threads=threads)
        wall, cpu = _timed(
            lambda pts=points: log_likelihood(
                pts, geometry, expected, 0.15, 0.6, 0.5, threads=threads
            ),
            20,
        )
        print(
            f"likelihood, 2000 poses x {len(points)} points x 13 parts: wall median "
            f"{np.median(wall) * 1e3:.1f} ms (min {min(wall) * 1e3:.1f}), "
            f"cpu median {np.median(cpu) * 1e3:.1f} ms"
        )
    for n in (300, 600):
        filt = SkeletonFilter(shape, SKELETON_PARAMS.create({"threads": threads}), seed=0)
        filt.reset(truth)
        clouds = iter([seen_cloud(truth, shape, rng, points=n) for _ in range(12)])
        filt.step(next(clouds), 1 / 30)
        errors = []

        def step(filt=filt, clouds=clouds, errors=errors) -> None:
            estimate = filt.step(next(clouds), 1 / 30)
            found = forward_kinematics(estimate, shape)[0][:16]
            errors.append(np.linalg.norm(found - joints, axis=1).mean())

        wall, cpu = _timed(step, 11)
        print(
            f"filter step, 2000 particles, {n} points: wall median {np.median(wall) * 1e3:.1f} ms "
            f"(min {min(wall) * 1e3:.1f}), cpu median {np.median(cpu) * 1e3:.1f} ms; "
            f"mean joint error {np.mean(errors) * 100:.1f} cm"
        )


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 1)
