"""``optrack bench WHAT``: measure one part of optrack and print its figures.

Each ``cmd_bench_<what>`` runs the benchmark of :mod:`optrack.bench` named
``<what>`` (imported only when it runs) and prints one JSON object on stdout
with ``--json``, a short summary on stderr without.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterable
from typing import Any

from optrack.cli import EXIT_OK, CommandError, add_json, emit_json, info

__all__ = [
    "BENCHES",
    "add_commands",
    "cmd_bench",
    "cmd_bench_calibration",
    "cmd_bench_detection",
    "cmd_bench_e2e",
    "cmd_bench_install",
    "cmd_bench_sim",
    "cmd_bench_site",
    "cmd_bench_skeleton",
    "cmd_bench_soak",
    "cmd_bench_tracking",
]


def _report(args: argparse.Namespace, result: dict[str, Any], summary: Iterable[str]) -> int:
    """The figures as one JSON object (``--json``), else the summary's lines on stderr."""
    if getattr(args, "json", False):
        emit_json(result)
    else:
        for line in summary:
            info(line)
    return EXIT_OK


def cmd_bench_sim(args: argparse.Namespace) -> int:
    """How fast the simulator renders Kinect v2 frames on one core."""
    from optrack.bench.sim import sim_bench

    result = sim_bench()
    return _report(
        args, result, [f"kinect2_fps {result['kinect2_fps']} (median of {result['runs_fps']})."]
    )


def cmd_bench_detection(args: argparse.Namespace) -> int:
    """Speed and accuracy of the people detector."""
    from optrack.bench.detection import detection_bench

    result = detection_bench(getattr(args, "pcl_binary", None))
    return _report(args, result, (f"  {key}: {value}" for key, value in result.items()))


def cmd_bench_tracking(args: argparse.Namespace) -> int:
    """Speed of the tracker, and accuracy against norfair."""
    from optrack.bench.tracking import tracking_bench

    result = tracking_bench()
    line = f"median update with 20 people and 10 sensors: {result['ms_per_update_20x10']} ms"
    return _report(args, result, [line])


def _calibration_summary(payload: dict[str, Any]) -> list[str]:
    from optrack.bench.calibration import OPENCV_FX

    lines = [
        f"global solve {payload['ba_seconds_10x300']:.2f} s (10 sensors x 300 views); "
        f"live feedback {payload['feedback_hz']:.1f} Hz; refinement "
        f"{payload['refinement_error_before_m'] * 100:.1f} -> "
        f"{payload['refinement_error_after_m'] * 100:.1f} cm"
    ]
    if payload.get("stereo_baseline_m") is not None:
        lines.append(
            f"OpenCV's images: left fx {payload['intrinsics_left_fx']:.2f} "
            f"({payload['intrinsics_left_fx_error_pct']:.2f} % from {OPENCV_FX}); stereo "
            f"baseline {payload['stereo_baseline_m'] * 1000:.3f} mm "
            f"({payload['stereo_baseline_error_pct']:.4f} % from cv2.stereoCalibrate), "
            f"rotation {payload['stereo_rotation_error_deg']:.4f} deg from it"
        )
        lines.append(
            f"replica of OpenCV's board, true fx {payload['intrinsics_replica_true_fx']:.2f}: "
            f"ours {payload['intrinsics_replica_fx_error_pct']:+.3f} %, OpenCV's sample "
            f"method {payload['intrinsics_replica_fx_error_pct_opencv_sample']:+.3f} %"
        )
    return lines


def cmd_bench_calibration(args: argparse.Namespace) -> int:
    """Speed (and accuracy) of the network solver."""
    from optrack.bench.calibration import calibration_bench

    result = calibration_bench()
    return _report(args, result, _calibration_summary(result))


def cmd_bench_e2e(args: argparse.Namespace) -> int:
    """Frame timestamp to UDP datagram, on this computer."""
    from optrack.bench.e2e import e2e_bench
    from optrack.runtime.process import setup_logging

    setup_logging("optrack bench e2e")
    result = e2e_bench()
    return _report(args, result, (f"{key}: {value}" for key, value in result.items()))


def cmd_bench_skeleton(args: argparse.Namespace) -> int:
    """Speed and accuracy of the skeleton stage on real CMU motion."""
    from optrack.bench.common import shared_data
    from optrack.bench.skeleton import all_clips, skeleton_bench

    clips = None
    if getattr(args, "clips", None):
        clips = tuple(c.strip() for c in args.clips.split(",") if c.strip())
        clips = tuple(c if c.endswith(".bvh") else f"{c}.bvh" for c in clips)
        unknown = sorted(set(clips) - set(all_clips()))
        if unknown:
            raise CommandError(
                f"--clips names {', '.join(unknown)}, not a clip of "
                f"{shared_data() / 'mocap'}; choose among {', '.join(all_clips()) or 'none'}."
            )
    for name in ("seeds", "jobs"):
        if getattr(args, name, 1) < 1:
            raise CommandError(f"--{name} must be at least 1 (got {getattr(args, name)}).")
    if getattr(args, "seconds", 4.0) <= 0:
        raise CommandError(f"--seconds must be positive (got {args.seconds:g}).")
    result = skeleton_bench(
        seconds=getattr(args, "seconds", 4.0),
        clips=clips,
        seeds=getattr(args, "seeds", 1),
        jobs=getattr(args, "jobs", 1),
        config=getattr(args, "config", None),
    )
    if "skipped" in result:
        return _report(args, result, [result["skipped"]])
    three = result["accuracy"]["3_sensors"]
    line = (
        f"{result['fps_1person_3sensors']} fps (one person, 3 sensors), "
        f"{result['fps_4people_3sensors']} per person with four (reference workload "
        f"{result['reference_ms']} ms of CPU); 3 sensors: mean marker error "
        f"{three['mean_error_m']} m, {three['lost_pct']} % lost "
        f"({len(result['clips'])} clip(s) x {result['seeds']} seed(s))"
    )
    return _report(args, result, [line])


def cmd_bench_install(args: argparse.Namespace) -> int:
    """The Debian package's size and first start, installed on this computer (root)."""
    from optrack.bench.install import install_bench

    result = install_bench()
    line = (
        f"deb {result['deb_mb']} MB, installed {result['installed_mb']} MB "
        f"(.venv {result['venv_mb']} MB), first tracks {result['first_tracks_s']} s"
    )
    return _report(args, result, [line])


def cmd_bench_site(args: argparse.Namespace) -> int:
    """A ``peer`` site across network namespaces: link cut, tracker kill, intruders."""
    from optrack.bench.site import site_bench

    result = site_bench()
    return _report(args, result, (f"{key}: {value}" for key, value in result.items()))


def cmd_bench_soak(args: argparse.Namespace) -> int:
    """A 3-sensor site left running: memory growth, restarts, dropped frames."""
    from optrack.bench.soak import soak_bench

    result = soak_bench(float(args.minutes))
    return _report(args, result, (f"{key}: {value}" for key, value in result.items()))


#: ``optrack bench WHAT``: each benchmark's handler.
BENCHES = {
    "sim": cmd_bench_sim,
    "detection": cmd_bench_detection,
    "tracking": cmd_bench_tracking,
    "calibration": cmd_bench_calibration,
    "e2e": cmd_bench_e2e,
    "skeleton": cmd_bench_skeleton,
    "install": cmd_bench_install,
    "site": cmd_bench_site,
    "soak": cmd_bench_soak,
}


def cmd_bench(args: argparse.Namespace) -> int:
    """The ``optrack bench`` command: the handler of the benchmark asked for."""
    return BENCHES[args.what](args)


def add_commands(commands: Any, command: Any) -> None:
    """Declare this package's commands on the ``optrack`` parser (see optrack/cli.py)."""
    p = command(
        "bench",
        "Measure speed, memory and accuracy of one part of optrack.",
        "optrack.bench.cli:cmd_bench",
    )
    p.add_argument(
        "what",
        choices=tuple(BENCHES),
        help="what to measure",
    )
    p.add_argument(
        "--minutes", type=float, default=10.0, help="soak: how long the site runs (e.g. 0.5)"
    )
    p.add_argument(
        "--pcl-binary",
        help="detection: PCL's people_bench harness to time against, pinned to one core",
    )
    p.add_argument(
        "--clips",
        help="skeleton: the mocap clips to score, comma-separated names "
        "(default: every clip of ../shared/data/mocap)",
    )
    p.add_argument(
        "--seeds", type=int, default=1, help="skeleton: tracker seeds per clip and setting"
    )
    p.add_argument(
        "--seconds", type=float, default=4.0, help="skeleton: seconds each clip is performed"
    )
    p.add_argument(
        "--jobs",
        type=int,
        default=1,
        help="skeleton: accuracy runs at once (processes; the speed runs stay alone)",
    )
    p.add_argument(
        "--config",
        help="skeleton: YAML parameter file (its skeleton and skeleton_fusion stages)",
    )
    add_json(p)
