"""A stand-in node for tests/runtime/test_starter.py: ``main(args)`` reports what a node
started by :class:`optrack.runtime.starter.NodeStarter` finds, to the file ``args[0]``."""

from __future__ import annotations

import json
import os
import signal
import sys
import time


def main(args: list[str]) -> int:
    report, action = args[0], args[1]
    found = {
        "imported": "optrack.detection.pipeline" in sys.modules,  # before this node imports
        "environ": dict(os.environ),
        "ppid": os.getppid(),
        "sid": os.getsid(0),
        "pid": os.getpid(),
        "argv": sys.argv,
        "cwd": os.getcwd(),
        "stdout_is_stderr": os.path.samestat(os.fstat(1), os.fstat(2)),
    }
    with open(f"/proc/{os.getpid()}/comm") as comm:
        found["comm"] = comm.read().strip()
    with open(report, "w") as out:
        json.dump(found, out)
    if action == "wait":  # until SIGTERM
        signal.signal(signal.SIGTERM, lambda number, frame: sys.exit(3))
        time.sleep(60)
    return int(action) if action.isdigit() else 0


if __name__ == "__main__":  # started as `python -m` (the launcher without its fork server)
    sys.exit(main(sys.argv[1:]))
