"""The runtime's commands: ``optrack run``, ``optrack node detect|track``, ``optrack site init``.

Each handler (imported when its command runs, so that ``optrack --help`` stays
fast) reads its options and starts what :mod:`optrack.runtime.process`
(a node) or :mod:`optrack.runtime.site` (a whole site) runs; a user error (a
bad URI, an unreachable bus) exits 1 with one sentence.
"""

from __future__ import annotations

import argparse
from typing import Any

from optrack.cli import add_group

__all__ = [
    "add_commands",
    "cmd_calibrate_live",
    "cmd_node_detect",
    "cmd_node_track",
    "cmd_run",
    "cmd_site_init",
]

INSECURE_HELP = (
    "join a peer/client/router bus without site keys (no TLS, no access control); every "
    "status says so"
)


def cmd_node_detect(args: argparse.Namespace) -> int:
    """``optrack node detect --sensor URI --site NAME [--config FILE] [--insecure]``."""
    from optrack.runtime.process import run_detector_node

    return run_detector_node(args.sensor, args.site, args.config, insecure=args.insecure)


def cmd_node_track(args: argparse.Namespace) -> int:
    """``optrack node track --site NAME [--config FILE] [--insecure]`` (with the outputs
    unless ``node.outputs`` is off)."""
    from optrack.runtime.process import run_tracker_node

    return run_tracker_node(args.site, args.config, insecure=args.insecure)


def cmd_site_init(args: argparse.Namespace) -> int:
    """``optrack site init [--out DIR] [--nodes A,B] [--stations C] [--site NAME] [--json]``:
    a site's authority and one certificate per node and operator station."""
    from optrack.cli import emit_json, info
    from optrack.net.security import SiteIdentities, init_site

    def names(text: str | None) -> list[str]:
        return [n.strip() for n in (text or "").split(",") if n.strip()]

    made = init_site(args.out, names(args.nodes), names(args.stations), site=args.site)
    identities = SiteIdentities(args.out)
    if args.json:
        emit_json({"folder": str(identities.folder), "made": made, "roles": identities.roles})
    else:
        described = ", ".join(f"{n} ({r})" for n, r in sorted(identities.roles.items()))
        info(
            f"{identities.folder}: made {len(made)} identit{'y' if len(made) == 1 else 'ies'}; "
            f"it holds {described or 'no identity yet'}. Copy the folder to each computer of "
            "the site and set bus.keys to it (keep ca-key.pem on this one only)."
        )
    return 0


def cmd_run(args: argparse.Namespace) -> int:
    """``optrack run [--headless] [--seconds S] [--udp HOST:PORT] [--config FILE]
    [--recording PATH [--speed S] [--loop]] [--skeleton] [--nodes all|tracker|detectors]
    [--insecure]``."""
    from optrack.outputs.streams import DEFAULT_UDP_PORT
    from optrack.outputs.udp import parse_destinations, resolve_destination
    from optrack.runtime.config import load_node_config
    from optrack.runtime.process import setup_logging
    from optrack.runtime.site import Site

    for text in args.udp or ():  # refused here, not by a tracker node restarting in a loop
        for host, port in parse_destinations(text, DEFAULT_UDP_PORT, "--udp destination"):
            resolve_destination("--udp", host, port)
    insecure = getattr(args, "insecure", False)
    config = load_node_config(args.config, {"bus": {"insecure": True}} if insecure else None)
    setup_logging("optrack run")
    site = Site(
        config,
        udp=args.udp,
        headless=args.headless,
        seconds=args.seconds,
        recording=getattr(args, "recording", None),
        speed=getattr(args, "speed", 1.0),
        loop=getattr(args, "loop", False),
        skeleton=getattr(args, "skeleton", False),
        nodes=getattr(args, "nodes", "all"),
    )
    return site.run()


def add_commands(commands: Any, command: Any) -> None:
    """Declare ``optrack run`` and ``optrack node detect|track`` on the ``optrack`` parser."""
    p = command(
        "run",
        "Run the embedded site (sensors, detectors, tracker) and stream to the outputs.",
        "optrack.runtime.cli:cmd_run",
    )
    p.add_argument("--headless", action="store_true", help="no window")
    p.add_argument("--seconds", type=float, help="stop after this many seconds")
    p.add_argument(
        "--udp",
        action="append",
        metavar="HOST:PORT",
        help="UDP JSON destination (default 127.0.0.1:21234)",
    )
    p.add_argument("--config", help="YAML site configuration")
    p.add_argument(
        "--recording",
        metavar="PATH",
        help="play this recording through the pipeline (its sensors as the detector nodes)",
    )
    p.add_argument(
        "--speed", type=float, default=1.0, help="--recording: times the recorded pace (0.25-4)"
    )
    p.add_argument(
        "--loop", action="store_true", help="--recording: play it again at its end (else stop)"
    )
    p.add_argument(
        "--skeleton",
        action="store_true",
        help="track skeletons too (skeleton_live.enabled; a skeleton node is started)",
    )
    p.add_argument(
        "--nodes",
        choices=("all", "tracker", "detectors"),
        default="all",
        help="a site over several computers: start only this computer's part (tracker: "
        "every node but the detectors; detectors: the detector nodes of site.sensors)",
    )
    p.add_argument(
        "--insecure",
        action="store_true",
        help="a peer site without keys: no TLS, no access control (anyone on the network may "
        "join); its nodes join the same way and every status says so",
    )

    node = add_group(
        commands, "node", "Run one node of a distributed site.", "node_command", "NODE"
    )
    q = command(
        "detect",
        "Detector node: capture one sensor, detect, publish detections.",
        "optrack.runtime.cli:cmd_node_detect",
        node,
    )
    q.add_argument("--sensor", required=True, metavar="URI", help="sensor URI")
    q.add_argument("--site", required=True, help="site name")
    q.add_argument("--config", help="YAML configuration")
    q.add_argument("--insecure", action="store_true", help=INSECURE_HELP)
    q = command(
        "track",
        "Tracker node: all detections in, tracks out.",
        "optrack.runtime.cli:cmd_node_track",
        node,
    )
    q.add_argument("--site", required=True, help="site name")
    q.add_argument("--config", help="YAML configuration")
    q.add_argument("--insecure", action="store_true", help=INSECURE_HELP)
    _add_site_commands(commands, command)


def _add_site_commands(commands: Any, command: Any) -> None:
    """Declare ``optrack site init``."""
    site = add_group(commands, "site", "A site's keys.", "site_command", "STEP")
    q = command(
        "init",
        "Make a site's keys: an authority, one certificate per node and operator station.",
        "optrack.runtime.cli:cmd_site_init",
        site,
    )
    q.add_argument("--out", default="site-keys", metavar="DIR", help="folder (default site-keys)")
    q.add_argument(
        "--nodes",
        metavar="NAME,...",
        help="node names: tracker, skeleton, outputs, site (the launcher) or a sensor's id "
        "(a detector node)",
    )
    q.add_argument("--stations", metavar="NAME,...", help="operator stations (GUI computers)")
    q.add_argument("--site", default="site", help="site name written in the certificates")
    q.add_argument("--json", action="store_true", help="print what was made as JSON")


def cmd_calibrate_live(args: argparse.Namespace) -> int:
    """``optrack calibrate live``: the calibration wizard without a window, against a
    running site: extrinsics, floor, (refinement), then save and publish."""
    import time

    from optrack.calibration.board import Checkerboard
    from optrack.cli import emit_json, info
    from optrack.net.bus import Bus
    from optrack.runtime.calibration_headless import HeadlessPlan, calibrate_headless
    from optrack.runtime.calibration_live import LiveCalibration
    from optrack.runtime.config import load_node_config

    config = load_node_config(args.config)  # knows calibration_live: imported above
    site = args.site or str(config["site"].name)
    board = Checkerboard.parse(args.board, args.square)
    board.require_asymmetric()
    plan = HeadlessPlan(
        out=args.out,
        extrinsics_s=float(args.extrinsics_seconds),
        min_views=int(args.min_views),
        floor_s=float(args.floor_seconds),
        floor_views=int(args.floor_views),
        refine_s=float(args.refine_seconds),
        publish=not args.no_publish,
    )
    bus = Bus(site, "calibrate", config["bus"])
    live = None
    try:
        started = time.monotonic()
        live = LiveCalibration(bus, board, params=config.params.get("calibration_live"))
        connect_s = time.monotonic() - started
        simulated = " (simulated: its operator moves the board)" if live.simulated else ""
        info(f"site '{site}': sensors {', '.join(live.sensors)}{simulated}")
        payload = calibrate_headless(live, plan, info, connect_s)
    finally:
        if live is not None:
            live.close()
        bus.close()
    if args.json:
        emit_json(payload)
    else:
        sent = f"; sent to the nodes of site '{site}'" if plan.publish else ""
        info(
            f"wrote {payload['out']}: {len(payload['sensors'])} sensors, RMS "
            f"{payload['rms_px']:.3f} px, world: {payload['world']}{sent}"
        )
    return 0
