"""``optrack detect INPUT``: people in a .pcd, a depth image, a recording or a live sensor.

Positions are in the camera frame for a single cloud or image (metres,
OpenCV axes) and in the world frame for a calibrated recording or sensor
(the sensor's ground frame when it has no calibration). ``ground`` is the
floor in the camera frame, ``a x + b y + c z + d = 0`` with the normal
pointing up towards the camera, so ``d`` is the camera's height.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import yaml

from optrack.errors import UserError

if TYPE_CHECKING:
    from optrack.detection.pipeline import PeopleDetector
    from optrack.detection.preprocessing import OrganisedCloud
    from optrack.geometry import Plane
    from optrack.params import Params
    from optrack.types import DetectionBatch, Intrinsics, RGBDFrame

__all__ = ["DetectError", "add_commands", "cmd_detect", "cmd_train_depth_classifier"]

IMAGE_SUFFIXES = (".png", ".tif", ".tiff", ".pgm", ".exr")


class DetectError(UserError):
    """An input ``optrack detect`` cannot use."""


def _info(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def _config_overrides(path: str | None) -> dict[str, Any]:
    """The ``detection`` values a YAML config file sets (the whole file is validated):
    parameters for every sensor, and per sensor model under the model's name."""
    from optrack.detection.params import SENSOR_MODELS, check_config_section
    from optrack.params import REGISTRY, ParamError, load_config

    if not path:
        return {}
    try:
        data = yaml.safe_load(Path(path).read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError):
        data = None
    section = data.get("detection") if isinstance(data, dict) else None
    if not isinstance(section, dict) or not set(section) & set(SENSOR_MODELS):
        load_config(path)  # validates every stage, with one clear sentence on error
        return dict(section or {})
    if not set(data) <= set(REGISTRY):
        load_config(path)  # names the unknown stage
    try:  # per sensor model values: the other stages as load_config checks them
        check_config_section(section)
        for stage, values in data.items():
            if stage != "detection":
                REGISTRY[stage].validate(values or {})
    except ParamError as error:
        raise ParamError(f"config file {path}: {error}") from None
    return dict(section)


def _params(args: argparse.Namespace, model: str | None) -> Params:
    from optrack.detection.params import SENSOR_MODELS, detection_params

    chosen = args.sensor_model or model
    if chosen and chosen not in SENSOR_MODELS:
        chosen = None  # a camera optrack has no figures for: the generic defaults
    return detection_params(chosen, args.preset, _config_overrides(args.config))


def _intrinsics(args: argparse.Namespace, what: str, width: int, height: int) -> Intrinsics:
    from optrack.types import Intrinsics

    if not args.intrinsics:
        raise DetectError(
            f"{what} needs the camera intrinsics; give --intrinsics fx,fy,cx,cy (pixels), "
            "e.g. --intrinsics 525,525,319.5,239.5 for a Kinect v1."
        )
    return Intrinsics.parse(args.intrinsics, width, height)


def _numbers(text: str, option: str, groups: int, size: int, example: str) -> list[list[float]]:
    """``groups`` groups of ``size`` numbers from ``"a,b;c,d;..."`` (an option's value)."""
    from optrack.detection.ground import GroundError

    parts = [g for g in text.split(";") if g.strip()]
    try:
        values = [[float(v) for v in g.replace(",", " ").split()] for g in parts]
    except ValueError:
        values = []
    if len(values) != groups or any(len(v) != size for v in values):
        raise GroundError(
            f"{option} must be {groups} groups of {size} numbers like '{example}'; got '{text}'."
        )
    if not all(np.isfinite(v).all() for v in values):
        raise GroundError(f"{option} must hold finite numbers; got '{text}'.")
    return values


def _ground_option(
    args: argparse.Namespace, cloud: OrganisedCloud | None, params: Params
) -> tuple[Plane | None, str]:
    """The floor the operator gave (``--ground``, ``--ground-points``,
    ``--ground-pixels`` or ``--ground-pick``) and how, or (None, "") for automatic.
    ``cloud`` is the frame the pixels and the pick refer to."""
    from optrack.detection.ground import (
        GroundError,
        ground_from_pixels,
        ground_from_points,
        parse_ground,
        semi_automatic_ground,
    )
    from optrack.detection.preprocessing import select_points, voxel_grid

    if getattr(args, "ground", None):
        return parse_ground(args.ground), "manual"
    if getattr(args, "ground_points", None):
        points = _numbers(args.ground_points, "--ground-points", 3, 3, "x1,y1,z1;x2,y2,z2;x3,y3,z3")
        return ground_from_points(*points), "points"
    pixels_text = getattr(args, "ground_pixels", None)
    pick_text = getattr(args, "ground_pick", None)
    if not (pixels_text or pick_text):
        return None, ""
    assert cloud is not None
    if pixels_text:
        pixels = _numbers(pixels_text, "--ground-pixels", 3, 2, "u1,v1;u2,v2;u3,v3")
        if any(v != round(v) for pixel in pixels for v in pixel):
            raise GroundError(
                f"--ground-pixels must be whole pixel numbers u,v; got '{pixels_text}'."
            )
        return ground_from_pixels(cloud, [(int(u), int(v)) for u, v in pixels]), "pixels"
    (pick,) = _numbers(pick_text, "--ground-pick", 1, 3, "x,y,z")
    points, _ = select_points(cloud, int(params.sampling_factor), float(params.max_distance))
    return semi_automatic_ground(voxel_grid(points, float(params.voxel_size)), pick, params), "pick"


def _detection_json(batch: DetectionBatch, camera_frame: bool) -> list[dict[str, Any]]:
    out = []
    for d in batch.detections:
        x, y, z = d.camera_xyz if camera_frame and d.camera_xyz else (d.x, d.y, d.z)
        item: dict[str, Any] = {
            "x": x,
            "y": y,
            "z": z,
            "height": d.height,
            "confidence": d.confidence,
            "box": list(d.box),
            "occluded": d.occluded,
            "out_of_view": d.out_of_view,
        }
        if not camera_frame:
            item["sensor"] = batch.sensor_id
            item["t"] = batch.stamp
            item["seq"] = batch.seq
            item["camera_xyz"] = list(d.camera_xyz) if d.camera_xyz else None
        out.append(item)
    return out


def _single(args: argparse.Namespace, source: Path) -> dict[str, Any]:
    """A .pcd file or a depth image: one frame, camera-frame output."""
    from optrack.detection.pipeline import PeopleDetector
    from optrack.detection.preprocessing import OrganisedCloud
    from optrack.types import RGBDFrame

    if source.suffix.lower() == ".pcd":
        import open3d as o3d

        from optrack.io.pcd import read_pcd

        with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
            cloud = read_pcd(source)  # a damaged file: our one sentence, not Open3D's warnings
        if not cloud.organized:
            raise DetectError(
                f"{source} is an unorganised cloud ({cloud.width} points in one row); the "
                "detector needs an organised cloud as the sensor saw it (WIDTH x HEIGHT pixels)."
            )
        intrinsics = _intrinsics(args, f"the cloud {source}", cloud.width, cloud.height)
        params = _params(args, "pcl")
        ground, how = _ground_option(args, OrganisedCloud(intrinsics, points=cloud.points), params)
        detector = PeopleDetector(params, sensor_id=source.stem, ground=ground)
        if how:
            detector.ground.source = how
        batch = detector.process_cloud(cloud.points, intrinsics, cloud.colors)
    else:
        from optrack.io.images import read_color_image, read_depth_image

        depth = read_depth_image(source)
        height, width = depth.shape
        intrinsics = _intrinsics(args, f"the depth image {source}", width, height)
        scale = args.depth_scale if args.depth_scale is not None else 0.001
        color = read_color_image(args.color) if args.color else None
        if color is not None and color.shape[:2] != depth.shape:
            raise DetectError(
                f"colour image {args.color} is {color.shape[1]}x{color.shape[0]} but the depth "
                f"image is {width}x{height}; give a registered colour image of the same size."
            )
        frame = RGBDFrame(
            depth,
            intrinsics,
            sensor_id=source.stem,
            depth_scale=scale if depth.dtype == np.uint16 else 1.0,
            color=color,
        )
        params = _params(args, None)
        ground, how = _ground_option(args, OrganisedCloud.from_frame(frame), params)
        detector = PeopleDetector(params, sensor_id=source.stem, ground=ground)
        if how:
            detector.ground.source = how
        batch = detector.process(frame)
    if batch.ground is None:
        raise DetectError(
            f"no floor was found in {source}: no large plane below the camera lies within "
            f"{detector.params.ground_max_tilt:g} degrees of its down direction; give the floor "
            "with --ground a,b,c,d (camera frame), or allow a steeper camera with "
            "detection: ground_max_tilt in a --config file."
        )
    return {
        "input": str(source),
        "frame_id": "camera",
        "detections": _detection_json(batch, camera_frame=True),
        "ground": list(batch.ground),
        "ground_source": detector.ground.source,
        "ms": batch.processing_ms,
        "frames": 1,
        "confidence_source": detector.last_judgements[0].source
        if detector.last_judgements
        else None,
        "luminance": detector.last_luminance,
    }


def _frames(args: argparse.Namespace) -> Iterator[tuple[RGBDFrame, Any]]:
    """Frames (with the SensorInfo of their sensor) of a recording or a live sensor."""
    from optrack.recording import Recording, is_recording

    if is_recording(args.input):
        recording = Recording(args.input)
        sensors = [args.sensor] if args.sensor else recording.sensor_ids
        for sensor in sensors:
            if sensor not in recording.sensors:
                raise DetectError(
                    f"recording {args.input} has no sensor '{sensor}' "
                    f"(it has: {', '.join(recording.sensor_ids)})."
                )
        for frame in recording.frames(sensors):
            yield frame, recording.sensors[frame.sensor_id]
        return
    import optrack.sim.sensor  # noqa: F401 - registers sim://
    from optrack.sensors import open_sensor

    with open_sensor(args.input) as sensor:
        info = sensor.info
        for frame in sensor:
            yield frame, info


def _stream(args: argparse.Namespace) -> dict[str, Any]:
    """A recording or a live sensor: frame after frame, one detector per sensor (the
    floor pixels or pick of a ground option refer to each sensor's first frame)."""
    from optrack.detection.pipeline import PeopleDetector
    from optrack.detection.preprocessing import OrganisedCloud

    detectors: dict[str, PeopleDetector] = {}
    detections: list[dict[str, Any]] = []
    times: list[float] = []
    count = 0
    for frame, info in _frames(args):
        if args.frames is not None and count >= args.frames:
            break
        detector = detectors.get(frame.sensor_id)
        if detector is None:
            pose = np.asarray(info.world_T_camera) if info.world_T_camera is not None else None
            params = _params(args, info.model)
            ground, how = _ground_option(args, OrganisedCloud.from_frame(frame), params)
            detector = PeopleDetector(
                params,
                sensor_id=frame.sensor_id,
                ground=ground,
                world_T_camera=pose,
            )
            if how:
                detector.ground.source = how
            detectors[frame.sensor_id] = detector
        batch = detector.process(frame)
        times.append(batch.processing_ms)
        detections.extend(_detection_json(batch, camera_frame=False))
        count += 1
        if not args.json:
            _info(
                f"{frame.sensor_id} #{frame.seq} t={frame.timestamp:.3f}s: "
                f"{len(batch.detections)} people ({batch.processing_ms:.1f} ms)"
            )
    if count == 0:
        raise DetectError(f"{args.input} gave no frames; check that it holds depth frames.")
    grounds = {
        sid: d.ground.plane.to_list() if d.ground.plane is not None else None
        for sid, d in detectors.items()
    }
    first = next(iter(grounds.values()))
    frame_ids = {
        ("world" if d.world_T_camera is not None else "ground") for d in detectors.values()
    }
    return {
        "input": args.input,
        "frame_id": frame_ids.pop() if len(frame_ids) == 1 else "mixed",
        "detections": detections,
        "ground": first,
        "grounds": grounds,
        "ground_source": next(iter(detectors.values())).ground.source,
        "ground_sources": {sid: d.ground.source for sid, d in detectors.items()},
        "ms": statistics.median(times),
        "frames": count,
        "sensors": sorted(detectors),
    }


def cmd_detect(args: argparse.Namespace) -> int:
    """The ``optrack detect`` command."""
    text = str(args.input)
    source = Path(text)
    if "://" in text:
        result = _stream(args)
    elif source.is_dir():
        from optrack.recording import is_recording

        if not is_recording(source):
            raise DetectError(
                f"{source} is a directory but not an optrack recording (no manifest.yaml); "
                "give a .pcd file, a depth image, a recording or a sensor URI."
            )
        result = _stream(args)
    elif not source.exists():
        raise DetectError(
            f"{source} does not exist; give a .pcd file, a depth image, a recording or a sensor URI."
        )
    elif source.suffix.lower() == ".pcd" or source.suffix.lower() in IMAGE_SUFFIXES:
        result = _single(args, source)
    else:
        raise DetectError(
            f"{source} is neither a .pcd cloud, a depth image ({', '.join(IMAGE_SUFFIXES)}), "
            "a recording nor a sensor URI."
        )
    if args.json:
        sys.stdout.write(json.dumps(result) + "\n")
        sys.stdout.flush()
    else:
        frame = result["frame_id"]
        _info(
            f"{len(result['detections'])} people in {result['frames']} frame(s) of {result['input']} "
            f"({frame} frame), median {result['ms']:.1f} ms per frame; floor {result['ground']}."
        )
        for d in result["detections"][:50]:
            _info(
                f"  x={d['x']:.3f} y={d['y']:.3f} z={d['z']:.3f} height={d['height']:.2f} "
                f"confidence={d['confidence']:.2f}"
            )
    return 0


def add_commands(commands: Any, command: Any) -> None:
    """Declare this package's commands on the ``optrack`` parser (see optrack/cli.py)."""
    from optrack.cli import add_json

    p = command(
        "detect",
        "Detect people in a point cloud, a recording or a live sensor.",
        "optrack.detection.cli:cmd_detect",
    )
    p.add_argument("input", help=".pcd file, depth image, recording directory or sensor URI")
    p.add_argument("--intrinsics", help="fx,fy,cx,cy in pixels (needed for a bare .pcd)")
    floor = p.add_mutually_exclusive_group()
    floor.add_argument(
        "--ground", help="ground plane a,b,c,d in the camera frame (default: automatic)"
    )
    floor.add_argument(
        "--ground-points",
        help="three floor points 'x1,y1,z1;x2,y2,z2;x3,y3,z3' (metres, camera frame)",
    )
    floor.add_argument(
        "--ground-pixels",
        help="three floor pixels 'u1,v1;u2,v2;u3,v3' of the organised .pcd or depth image",
    )
    floor.add_argument(
        "--ground-pick",
        help="x,y,z (metres, camera frame): the segmented plane nearest this point is the floor",
    )
    p.add_argument("--config", help="YAML parameter file")
    p.add_argument(
        "--sensor-model",
        choices=("kinect1", "kinect2", "sr4500", "stereo", "pcl", "default"),
        help="parameter defaults of this sensor model (default: the recording's; PCL's for a .pcd)",
    )
    p.add_argument("--preset", choices=("children",), help="parameter preset on top of the model")
    p.add_argument("--sensor", help="recording: only this sensor (default: all)")
    from optrack.io.arguments import count, positive_number

    p.add_argument("--frames", type=count, help="recording or sensor: stop after this many frames")
    p.add_argument("--color", help="depth image: registered colour image of the same size")
    p.add_argument(
        "--depth-scale",
        type=positive_number,
        help="depth image: metres per unit (default 0.001: millimetres)",
    )
    add_json(p)
    _add_train(commands, command)


def cmd_train_depth_classifier(args: argparse.Namespace) -> int:
    """``optrack train depth-classifier``: train the depth-only person classifier on
    simulated scenes and write it; the report has its held-out scores."""
    from optrack.cli import emit_json
    from optrack.sim.depth_training import split_parts, train_depth_classifier

    seeds = list(range(args.first_seed, args.first_seed + args.scenes))
    split_parts(len(seeds))  # refuses too few scenes before any is simulated
    out = Path(args.out)
    if not out.parent.is_dir():
        raise UserError(f"--out: folder {out.parent} does not exist.")
    model, report = train_depth_classifier(seeds, args.seconds, args.every, progress=_info)
    model.save(out)
    report["out"] = str(out)
    if args.json:
        emit_json(report)
    else:
        test = report["test"]
        print(
            f"{out}: held-out recall {test['recall']:.3f}, precision {test['precision']:.3f} "
            f"at threshold {report['threshold']:.2f} ({test['windows']} windows)"
        )
    return 0


def _add_train(commands: Any, command: Any) -> None:
    """``optrack train STEP``: models trained here."""
    from optrack.cli import add_group, add_json
    from optrack.io.arguments import count, positive_number

    train = add_group(commands, "train", "Train the detector's models.", "train_command", "STEP")
    p = command(
        "depth-classifier",
        "Train the depth-only person classifier on simulated scenes.",
        "optrack.detection.cli:cmd_train_depth_classifier",
        train,
    )
    p.add_argument("--out", required=True, help="model file to write (.npz)")
    p.add_argument("--scenes", type=count, default=40, help="simulated scenes (default 40)")
    p.add_argument("--first-seed", type=int, default=1000, help="the first scene's seed")
    p.add_argument(
        "--seconds", type=positive_number, default=6.0, help="each scene's length (default 6)"
    )
    p.add_argument("--every", type=count, default=4, help="detect every Nth frame (default 4)")
    add_json(p)
