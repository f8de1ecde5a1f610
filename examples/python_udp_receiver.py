#!/usr/bin/env python3
"""Receive optrack's tracks: OpenPTrack JSON over UDP, standard library only.

    python3 python_udp_receiver.py              # listen on 0.0.0.0:21234
    python3 python_udp_receiver.py --port 9000 --count 100

Each datagram is one JSON document (no trailing NUL byte): a frame of tracks
(``frame_id`` "world": id, x, y in metres on the floor, height in metres, age
in seconds, confidence) or a heartbeat every 0.25 s (``frame_id``
"heartbeat": the ids alive and the largest id given so far) or, while the
skeleton stage runs (``optrack run --skeleton``), a frame of skeletons
(``pose_tracks``, OpenPTrack v2's pose message: per person its id, height, state
and joints by name, each x, y, z in metres and a confidence).
"""

from __future__ import annotations

import argparse
import json
import socket


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--host", default="0.0.0.0", help="address to listen on")
    parser.add_argument("--port", type=int, default=21234, help="UDP port (OpenPTrack's: 21234)")
    parser.add_argument("--count", type=int, default=0, help="stop after this many datagrams")
    args = parser.parse_args()

    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind((args.host, args.port))
    print(f"listening on {args.host}:{args.port}", flush=True)
    received = 0
    while args.count == 0 or received < args.count:
        data, sender = sock.recvfrom(65536)
        received += 1
        message = json.loads(data)
        header = message["header"]
        stamp = header["stamp"]["sec"] + header["stamp"]["nsec"] * 1e-9
        if header["frame_id"] == "heartbeat":
            print(f"{stamp:.3f} alive {message['alive_IDs']} max {message['max_ID']}", flush=True)
            continue
        if "pose_tracks" in message:
            bodies = ", ".join(
                f"#{s['id']} {s['state']} head "
                + (
                    "({x:+.2f}, {y:+.2f}, {z:.2f})".format(**s["joints"]["HEAD"])
                    if "HEAD" in s["joints"]
                    else "unknown"
                )
                for s in message["pose_tracks"]
            )
            print(f"{stamp:.3f} skeletons {header['seq']}: {bodies or 'nobody'}", flush=True)
            continue
        people = ", ".join(
            f"#{t['id']} ({t['x']:+.2f}, {t['y']:+.2f}) {t['height']:.2f} m"
            for t in message["tracks"]
        )
        print(f"{stamp:.3f} frame {header['seq']}: {people or 'nobody'}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
