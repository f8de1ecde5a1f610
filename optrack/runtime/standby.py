"""A node process started ahead of need: ``python -m optrack.runtime.standby``.

Importing what a node needs (NumPy, OpenCV, Open3D, Zenoh, the detector) takes
a couple of CPU seconds, many more on a computer whose cores the running
detectors keep busy. So ``optrack run`` keeps one process that has done it
all and waits; when a node stops unexpectedly, the launcher hands its
command to this process on stdin (one JSON line: ``{"module": ...,
"args": [...]}``) and it becomes that node at once. A standby whose stdin
closes (the launcher stopped or died) exits.
"""

from __future__ import annotations

import importlib
import json
import sys

__all__ = ["main", "preload"]


def preload() -> None:
    """Import everything a detector, tracker or outputs node imports. (The command line
    that starts it, ``optrack.cli``, imports only the standard library and these.)"""
    import optrack.detection.pipeline  # noqa: F401
    import optrack.runtime.detector_node  # noqa: F401
    import optrack.runtime.outputs_node  # noqa: F401
    import optrack.runtime.process  # noqa: F401
    import optrack.runtime.tracker_node  # noqa: F401
    import optrack.sensors.uri  # noqa: F401
    import optrack.sim.sensor  # noqa: F401
    import optrack.tracking  # noqa: F401
    from optrack.runtime.config import load_node_config

    load_node_config(None)  # registers every stage's schema


def main() -> int:
    preload()
    line = sys.stdin.readline()
    if not line.strip():
        return 0  # not needed after all
    order = json.loads(line)
    sys.argv = [order["module"], *order["args"]]
    return int(importlib.import_module(order["module"]).main(order["args"]) or 0)


if __name__ == "__main__":
    sys.exit(main())
