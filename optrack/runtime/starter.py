"""How ``optrack run`` starts its nodes: forked from one process that imported them once.

A node imports NumPy, OpenCV, Open3D, SciPy, Zenoh and the detector before
it does anything: two to three CPU seconds on a small computer. A site of
three detectors and a tracker started as four fresh interpreters spent most
of its first start importing the same modules four times over, on two
cores. So the launcher starts a fork server (the standard library's
``multiprocessing`` forkserver, a fresh interpreter, not a fork of the
launcher) that imports :mod:`optrack.runtime.node_imports` once; every node
is then a fork of it that runs ``MODULE.main(ARGS)`` at once, the first ones
and any restarted later alike.

A node started this way behaves as one started with ``python -m MODULE ARGS``:
the launcher's environment and working directory at its start, its own
session (Ctrl-C reaches the launcher, which stops the nodes in order), its
output on the launcher's stderr, ``top`` showing its name. When the launcher
ends, the fork server ends; a node notices that its parent has gone
(``OPTRACK_PARENT_PID``) and stops. Should the fork server not start, nodes
start as their own interpreters, as before, and the log says so.
"""

from __future__ import annotations

import contextlib
import importlib
import logging
import multiprocessing
import os
import signal
import subprocess
import sys
from collections.abc import Mapping

from optrack.runtime.node import PARENT_ENV

__all__ = ["NodeProcess", "NodeStarter"]

log = logging.getLogger("optrack.runtime.site")

PRELOAD = "optrack.runtime.node_imports"


class NodeProcess:
    """A forked node, with the part of :class:`subprocess.Popen`'s interface the launcher
    uses (``pid``, ``poll``, ``wait``, ``send_signal``, ``terminate``, ``kill``)."""

    def __init__(self, process: multiprocessing.process.BaseProcess, argv: list[str]) -> None:
        self._process = process
        self.args = argv

    @property
    def pid(self) -> int:
        assert self._process.pid is not None
        return self._process.pid

    @property
    def returncode(self) -> int | None:
        return self._process.exitcode

    def poll(self) -> int | None:
        return self._process.exitcode

    def wait(self, timeout: float | None = None) -> int:
        self._process.join(timeout)
        code = self._process.exitcode
        if code is None:
            raise subprocess.TimeoutExpired(self.args, timeout or 0.0)
        return code

    def send_signal(self, sig: int) -> None:
        if self.poll() is None:
            os.kill(self.pid, sig)

    def terminate(self) -> None:
        self.send_signal(signal.SIGTERM)

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)


def _run_node(name: str, module: str, args: list[str], env: dict[str, str]) -> None:
    """A node's life in the forked process (``python -m MODULE ARGS`` without the imports)."""
    os.setsid()  # as start_new_session: Ctrl-C reaches the launcher only
    os.dup2(sys.stderr.fileno(), sys.stdout.fileno())  # the node's output on stderr
    env[PARENT_ENV] = str(os.getppid())  # the fork server: it ends with the launcher
    os.environ.clear()
    os.environ.update(env)
    sys.argv = [module, *args]
    with contextlib.suppress(OSError):  # what `top` and `ps -o comm` show
        with open("/proc/self/comm", "w") as comm:
            comm.write(name[:15])
    code = importlib.import_module(module).main(args)
    sys.exit(int(code or 0))


class NodeStarter:
    """Starts nodes forked from the fork server (see the module docstring).

    ``env``: what every node's environment has on top of the launcher's. ``server_env``:
    what the fork server's has, for what a library reads once when it loads (such as
    ``OPENBLAS_NUM_THREADS``); :meth:`prepare` sets it in the launcher's own environment,
    once, so that a fork server started again later has it too."""

    def __init__(self, env: Mapping[str, str], server_env: Mapping[str, str]) -> None:
        self.env = dict(env)
        self.server_env = dict(server_env)
        self._context = multiprocessing.get_context("forkserver")
        self._failed = False

    def prepare(self) -> None:
        """Start the fork server now: it imports while the launcher sets up the hub. The
        first :meth:`start` waits for its imports to end. Call it before the launcher
        starts threads: it changes the launcher's environment."""
        from multiprocessing import forkserver

        os.environ.update(self.server_env)
        self._context.set_forkserver_preload([PRELOAD])
        try:
            forkserver.ensure_running()
        except (OSError, ValueError) as error:
            self._fail(error)

    def _fail(self, error: BaseException) -> None:
        if not self._failed:
            log.warning(
                "the nodes' fork server did not start (%s); each node starts as its own "
                "Python process, which takes longer.",
                error,
            )
        self._failed = True

    def start(self, name: str, module: str, args: list[str]) -> NodeProcess | None:
        """The node ``name`` running ``MODULE.main(ARGS)``; None when the fork server
        cannot start it (then start ``python -m MODULE ARGS`` instead)."""
        if self._failed:
            return None
        env = {**os.environ, **self.env}
        process = self._context.Process(
            target=_run_node, args=(name, module, list(args), env), name=name, daemon=True
        )
        try:
            process.start()
        except (OSError, EOFError, ValueError) as error:
            self._fail(error)
            return None
        return NodeProcess(process, [sys.executable, "-m", module, *args])
