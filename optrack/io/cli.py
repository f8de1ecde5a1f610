"""``optrack cloud``: a depth image or a recording frame, back-projected into a .pcd file."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from optrack.cli import EXIT_OK, CommandError, add_json, emit_json, info
from optrack.io.arguments import index, positive_number

__all__ = ["add_commands", "cmd_cloud"]


def cmd_cloud(args: argparse.Namespace) -> int:
    """Back-project a depth image (or a recording's frame) into a .pcd file."""
    import numpy as np

    from optrack.geometry import backproject
    from optrack.io.images import read_color_image, read_depth_image
    from optrack.io.pcd import write_pcd
    from optrack.recording import Recording, is_recording
    from optrack.types import Intrinsics, RGBDFrame

    source = Path(args.input)
    if not args.out.lower().endswith(".pcd"):
        raise CommandError(f"--out {args.out} must name a .pcd file.")
    if is_recording(source):
        recording = Recording(source)
        sensor = args.sensor or recording.sensor_ids[0]
        frame = recording.frame(sensor, args.frame)
        if args.intrinsics:
            frame.intrinsics = Intrinsics.parse(args.intrinsics, *frame.depth.shape[::-1])
        if args.depth_scale is not None:
            frame.depth_scale = args.depth_scale
    else:
        if source.is_dir():
            raise CommandError(
                f"{source} is a directory but not an optrack recording (no manifest.yaml); "
                "give a depth image or a recording."
            )
        if not args.intrinsics:
            raise CommandError(
                "a depth image needs --intrinsics fx,fy,cx,cy (pixels), e.g. --intrinsics 525,525,320,240."
            )
        depth = read_depth_image(source)
        height, width = depth.shape
        intrinsics = Intrinsics.parse(args.intrinsics, width, height)
        scale = args.depth_scale if args.depth_scale is not None else 0.001
        if depth.dtype != np.uint16:
            scale = 1.0  # float images are metres
        color = read_color_image(args.color) if args.color else None
        if color is not None and color.shape[:2] != depth.shape:
            raise CommandError(
                f"colour image {args.color} is {color.shape[1]}x{color.shape[0]} but the depth "
                f"image is {width}x{height}; give a registered colour image of the same size."
            )
        frame = RGBDFrame(depth, intrinsics, sensor_id=source.stem, depth_scale=scale, color=color)
    cloud = backproject(frame.depth_m(), frame.intrinsics)
    colors = (
        frame.color
        if frame.color is not None and frame.color.shape[:2] == frame.depth.shape
        else None
    )
    write_pcd(args.out, cloud, colors)
    valid = int(np.count_nonzero(np.isfinite(cloud[..., 2])))
    height, width = frame.depth.shape
    if args.json:
        emit_json(
            {
                "out": args.out,
                "points": valid,
                "width": width,
                "height": height,
                "color": colors is not None,
            }
        )
    else:
        info(f"wrote {args.out}: {width}x{height} organised cloud, {valid} valid points.")
    return EXIT_OK


def add_commands(commands: Any, command: Any) -> None:
    """Declare this package's commands on the ``optrack`` parser (see optrack/cli.py)."""
    p = command(
        "cloud",
        "Back-project a depth image or a recording frame into a .pcd point cloud.",
        "optrack.io.cli:cmd_cloud",
    )
    p.add_argument("input", help="16-bit depth image (TIFF/PNG) or recording directory")
    p.add_argument(
        "--intrinsics",
        help="fx,fy,cx,cy in pixels (required for an image; a recording has its own)",
    )
    p.add_argument(
        "--depth-scale",
        type=positive_number,
        help="metres per depth unit (default 0.001: millimetres)",
    )
    p.add_argument("--color", help="registered colour image for a depth image (same size)")
    p.add_argument("--sensor", help="recording: sensor id (default: the first)")
    p.add_argument(
        "--frame", type=index, default=0, help="recording: frame number of that sensor (default 0)"
    )
    p.add_argument("--out", required=True, help="output .pcd file")
    add_json(p)
