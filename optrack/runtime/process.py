"""A node's process: its log lines, its stop on a signal, its exit, and the start of each
kind of node from its configuration.

Each node process logs one line per event on stderr (``optrack node detect
cam0: ...``), stops cleanly on Ctrl-C or SIGTERM (last status published,
bus closed) and exits 0; a user error (a bad URI, an unreachable bus)
raises :class:`~optrack.errors.UserError` (one sentence). The ``optrack node``
commands (``optrack.runtime.cli``) and ``python -m optrack.runtime.outputs_node``
start nodes through :func:`run_detector_node`, :func:`run_tracker_node` and
:func:`run_outputs_node`.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import sys
from collections.abc import Callable, Iterator

from optrack.errors import UserError
from optrack.net.bus import Bus
from optrack.net.clock import ClockSync, local_clock
from optrack.net.keys import check_name
from optrack.params import Params
from optrack.recording import SensorInfo
from optrack.runtime.calibration_store import CalibrationStore
from optrack.runtime.config import NodeConfig, load_node_config, state_dir
from optrack.runtime.node import PARENT_ENV
from optrack.sensors.base import Sensor, SensorError

__all__ = [
    "detection_params_for",
    "finish",
    "module_main",
    "nice",
    "open_node_sensor",
    "run_detector_node",
    "run_outputs_node",
    "run_tracker_node",
    "setup_logging",
    "stop_on_signals",
]

REPLAY_OPTIONS = ("id", "loop", "speed", "realtime", "paused")
_TRUE = {"1", "true", "yes", "on"}
_FALSE = {"0", "false", "no", "off"}


def module_main(
    argv: list[str] | None, module: str, description: str, run: Callable[[str, str | None], int]
) -> int:
    """``python -m MODULE --site NAME [--config FILE]``: a node started as a module."""
    import argparse

    parser = argparse.ArgumentParser(prog=f"python -m {module}", description=description)
    parser.add_argument("--site", required=True, help="site name")
    parser.add_argument("--config", help="YAML configuration")
    args = parser.parse_args(argv)
    return run(args.site, args.config)


def setup_logging(label: str) -> None:
    """One line per message on stderr, prefixed with the command and node."""
    root = logging.getLogger("optrack")
    for handler in list(root.handlers):
        if getattr(handler, "_optrack_runtime", False):
            root.removeHandler(handler)
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter(f"{label}: %(message)s"))
    handler._optrack_runtime = True  # type: ignore[attr-defined]
    root.addHandler(handler)
    root.setLevel(logging.INFO)
    root.propagate = False


@contextlib.contextmanager
def stop_on_signals(stop: Callable[[], None]) -> Iterator[None]:
    """Ctrl-C and SIGTERM call ``stop`` (the node then ends its loop cleanly)."""
    previous = {}
    for sig in (signal.SIGINT, signal.SIGTERM):
        previous[sig] = signal.signal(sig, lambda number, frame: stop())
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def finish(code: int) -> int:
    """Return ``code``; a node started by ``optrack run`` exits at once instead (everything
    is closed by then, and the interpreter's teardown of Open3D and friends takes seconds
    that would only slow the site's stop)."""
    if os.environ.get(PARENT_ENV):
        sys.stdout.flush()
        sys.stderr.flush()
        logging.shutdown()
        os._exit(code)
    return code


def nice(params: Params) -> None:
    """Lower this process's CPU priority by ``node.nice``."""
    increment = int(params.nice)
    if increment > 0 and hasattr(os, "nice"):
        os.nice(increment)


def _flag(uri: str, name: str, value: str) -> bool:
    if value.lower() in _TRUE:
        return True
    if value.lower() in _FALSE:
        return False
    raise SensorError(f"sensor URI '{uri}': {name} must be true or false; got '{value}'.")


def _loop_option(uri: str, value: str) -> bool | str:
    """``loop=true|false`` (restart, off) or a mode of :data:`~optrack.runtime.replay.LOOP_MODES`."""
    from optrack.runtime.replay import LOOP_MODES

    if value.lower() in LOOP_MODES:
        return value.lower()
    if value.lower() in _TRUE | _FALSE:
        return _flag(uri, "loop", value)
    raise SensorError(
        f"sensor URI '{uri}': loop must be true, false or one of {', '.join(LOOP_MODES)}; "
        f"got '{value}'."
    )


def open_node_sensor(uri: str, config: NodeConfig, clock: Callable[[], float]) -> Sensor:
    """The sensor a detector node reads. A recording (``file://``) plays as a live camera
    on the node's clock (:class:`~optrack.runtime.replay.LiveReplay`); other URIs open
    through :func:`optrack.sensors.uri.open_sensor`."""
    import optrack.sim.sensor  # noqa: F401 - registers sim://
    from optrack.runtime.replay import LiveReplay
    from optrack.sensors.uri import open_sensor, parse_uri

    parsed = parse_uri(uri)
    if parsed.scheme != "file":
        return open_sensor(parsed, config.params)
    options = parsed.options
    unknown = sorted(set(options) - set(REPLAY_OPTIONS))
    if unknown:
        raise SensorError(
            f"sensor URI '{uri}' sets '{unknown[0]}', which a detector node's replay does not "
            f"have (it has: {', '.join(REPLAY_OPTIONS)})."
        )
    if "realtime" in options and not _flag(uri, "realtime", options["realtime"]):
        raise SensorError(
            f"sensor URI '{uri}': a detector node plays recordings in real time, as a live "
            "camera; remove realtime=false (use 'optrack detect' to process every frame)."
        )
    loop = _loop_option(uri, options.get("loop", "false"))
    paused = _flag(uri, "paused", options["paused"]) if "paused" in options else False
    try:
        speed = float(options.get("speed", "1"))
    except ValueError:
        raise SensorError(f"sensor URI '{uri}': speed must be a number.") from None
    if not parsed.target:
        raise SensorError(f"sensor URI '{uri}' names no recording; write file://PATH[#SENSOR].")
    sensor = LiveReplay(
        parsed.target,
        parsed.fragment or None,
        loop=loop,
        speed=speed,
        clock=clock,
        sensor_id=parsed.sensor_id,
        uri=uri,
        paused=paused,
    )
    sensor.open()
    return sensor


def detection_params_for(info: SensorInfo, config: NodeConfig) -> Params:
    """The sensor model's detection defaults with the config file's values on top."""
    from optrack.detection.params import SENSOR_MODELS, detection_params

    model = info.model if info.model in SENSOR_MODELS else None
    return detection_params(model, overrides=config.explicit.get("detection"))


# ------------------------------------------------------------------ nodes


def run_detector_node(
    sensor_uri: str, site: str, config_path: str | None = None, insecure: bool = False
) -> int:
    """A detector node (``optrack node detect``): read one sensor, detect, publish.
    ``insecure``: ``bus.insecure`` on (``--insecure``)."""
    from optrack.runtime.detector_node import DetectorNode
    from optrack.runtime.replay import LiveReplay

    config = load_node_config(config_path, {"bus": {"insecure": True}} if insecure else None)
    check_name("site", site)
    nice(config["node"])
    clock = local_clock(config["clock"])
    setup_logging("optrack node detect")
    sensor = open_node_sensor(sensor_uri, config, clock)
    try:
        name = check_name("sensor", sensor.info.id)
        setup_logging(f"optrack node detect {name}")
        bus = Bus(site, name, config["bus"], host=False)
    except BaseException:
        sensor.close()
        raise
    try:
        sync = ClockSync(bus, config["clock"], clock)
        sync.measure()  # synchronise before the first frame when the tracker is there
        sync.start()
        if isinstance(sensor, LiveReplay):
            sensor.lock_phase(sync.offset_s)  # every replayed sensor at the same instant
        node = DetectorNode(
            bus,
            sensor,
            detection_params_for(sensor.info, config),
            config["node"],
            sync,
            CalibrationStore(state_dir(config, site) / name),
            skeleton={stage: config[stage] for stage in ("skeleton_live", "skeleton_fusion")},
        )
        node.ask_calibration()
        logging.getLogger("optrack.runtime").info(
            "publishing %s on optrack/%s/detections/%s", sensor.info.uri or name, site, name
        )
        with stop_on_signals(node.stop):
            code = node.run()
    finally:
        sensor.close()
        bus.close()
    return finish(code)


def run_tracker_node(site: str, config_path: str | None = None, insecure: bool = False) -> int:
    """The tracker node (``optrack node track``), with the outputs in its process unless
    ``node.outputs`` is off. ``insecure``: ``bus.insecure`` on (``--insecure``)."""
    from optrack.runtime.outputs_node import OutputsNode
    from optrack.runtime.tracker_node import TrackerNode

    config = load_node_config(config_path, {"bus": {"insecure": True}} if insecure else None)
    check_name("site", site)
    nice(config["node"])
    setup_logging("optrack node track")
    host = str(config["bus"].mode) == "local"
    bus = Bus(site, "tracker", config["bus"], host=host)
    tracker = outputs = None
    try:
        if config["node"].outputs:  # in this process, fed straight from the tracker's loop
            outputs = OutputsNode(bus, config["node"], config["outputs"], subscribe=False)
            described = (
                ", ".join(f"{d.kind} {d.address}" for d in outputs.outputs.status()) or "none"
            )
            logging.getLogger("optrack.runtime").info("outputs: %s", described)
        tracker = TrackerNode(
            bus,
            config["node"],
            CalibrationStore(state_dir(config, site) / "tracker"),
            live={stage: config[stage] for stage in ("tracking", "appearance", "smoothing")},
            sinks=[outputs.send] if outputs is not None else [],
        )
        if host:
            logging.getLogger("optrack.runtime").info(
                "hosting site '%s' on tcp/127.0.0.1:%d (this computer only)",
                site,
                int(config["bus"].local_port),
            )
        with stop_on_signals(tracker.stop):
            if outputs is not None:
                outputs.start_status()
            code = tracker.run()
    finally:
        if outputs is not None:
            outputs.close()
        if tracker is not None:
            tracker.close()
        bus.close()
    return finish(code)


def run_outputs_node(site: str, config_path: str | None = None) -> int:
    """The outputs as a process of their own (``python -m optrack.runtime.outputs_node``)."""
    from optrack.runtime.outputs_node import OutputsNode

    config = load_node_config(config_path)
    check_name("site", site)
    nice(config["node"])
    setup_logging("optrack outputs")
    bus = Bus(site, "outputs", config["bus"], host=False)
    node = None
    try:
        node = OutputsNode(bus, config["node"], config["outputs"])
        with stop_on_signals(node.stop):
            code = node.run()
    except UserError as error:
        logging.getLogger("optrack.runtime").error("%s", error)
        code = 1
    finally:
        if node is not None:
            node.close()
        bus.close()
    return finish(code)
