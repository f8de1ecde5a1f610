"""Several computers on this one: Linux network namespaces joined by a bridge.

:class:`Lab` makes one network namespace per computer, each with an ``eth0``
(one end of a veth pair) and its own address in a private /24 (10.231.X.0/24),
and one *switch* namespace holding a bridge that the other ends join. The
bridge lives in a namespace of its own and has no address and no uplink, so
nothing the computers send can leave them; the host's own namespace is not
touched (the veth pairs are created there and moved at once).

Every name starts with ``otk<pid>``: what a crashed run left behind (its pid
no longer alive) is removed by the next :class:`Lab`, and two runs at the same
time never share a name. :meth:`Lab.close` deletes everything (deleting a
namespace deletes its interfaces and the bridge); use the lab as a context
manager so that it also happens on failure.

Needs root and ``ip`` (iproute2) with network namespace support:
:func:`netns_problem` says in one sentence why not, else None.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from collections.abc import Sequence
from typing import Any

__all__ = ["PREFIX", "Lab", "clean_stale", "netns_problem"]

PREFIX = "otk"  # every namespace of a lab: otk<pid><role>
_OWN = re.compile(rf"^{PREFIX}(\d+)")


class NetnsError(RuntimeError):
    """An ``ip`` command of the lab failed."""


def ip(*args: str, check: bool = True) -> subprocess.CompletedProcess[str]:
    """Run ``ip ARGS``; a failure raises :class:`NetnsError` with its stderr."""
    result = subprocess.run(["ip", *args], capture_output=True, text=True, check=False)
    if check and result.returncode != 0:
        raise NetnsError(f"ip {' '.join(args)}: {result.stderr.strip()}")
    return result


def netns_problem() -> str | None:
    """Why network namespaces cannot be made here (one sentence), or None."""
    if not hasattr(os, "geteuid") or os.geteuid() != 0:
        return "network namespaces need root (this process is not root)"
    if shutil.which("ip") is None:
        return "the 'ip' command (iproute2) is not installed"
    probe = f"{PREFIX}{os.getpid()}probe"
    made = ip("netns", "add", probe, check=False)
    if made.returncode != 0:
        return f"'ip netns add' is refused here ({made.stderr.strip() or 'no reason given'})"
    try:
        for kind in (["veth", "peer", "name", "b0"], ["bridge"]):
            link = ip("-n", probe, "link", "add", "a0", "type", *kind, check=False)
            if link.returncode != 0:
                return f"a {kind[0]} link cannot be made here ({link.stderr.strip()})"
            ip("-n", probe, "link", "del", "a0", check=False)
    finally:
        ip("netns", "del", probe, check=False)
    return None


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def clean_stale() -> list[str]:
    """Delete the namespaces that a lab whose process has ended left behind."""
    listed = ip("netns", "list", check=False).stdout.split("\n")
    removed = []
    for line in listed:
        name = line.split(" ")[0].strip()
        found = _OWN.match(name)
        if found and int(found.group(1)) != os.getpid() and not _alive(int(found.group(1))):
            ip("netns", "del", name, check=False)
            removed.append(name)
    return removed


class Lab:
    """Computers (network namespaces) on one bridge; see the module docstring.

    ``hosts``: the computers' short names (letters and digits, a few
    characters), addressed ``10.231.<subnet>.<k+1>`` in that order.
    """

    def __init__(self, hosts: Sequence[str], subnet: int | None = None) -> None:
        self.tag = f"{PREFIX}{os.getpid()}"
        self.subnet = subnet if subnet is not None else 16 + os.getpid() % 200
        self.hosts = list(hosts)
        self.switch = f"{self.tag}sw"
        self.made: list[str] = []
        self.addresses = {h: f"10.231.{self.subnet}.{k + 1}" for k, h in enumerate(self.hosts)}

    def netns(self, host: str) -> str:
        return f"{self.tag}{host}"

    def port(self, host: str) -> str:
        """The switch's side of ``host``'s cable."""
        return f"{self.tag}{host}"[:13] + "p"

    def __enter__(self) -> Lab:
        self.open()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def _add_netns(self, name: str) -> None:
        ip("netns", "add", name)
        self.made.append(name)
        ip("-n", name, "link", "set", "lo", "up")

    def open(self) -> None:
        """Make the switch, then each computer and its cable."""
        clean_stale()
        try:
            self._add_netns(self.switch)
            ip("-n", self.switch, "link", "add", "br0", "type", "bridge")
            ip("-n", self.switch, "link", "set", "br0", "up")
            for host in self.hosts:
                self._add_host(host)
        except BaseException:
            self.close()
            raise

    def _add_host(self, host: str) -> None:
        name, port = self.netns(host), self.port(host)
        self._add_netns(name)
        temp = f"{port[:-1]}e"
        ip("link", "add", temp, "type", "veth", "peer", "name", port)
        ip("link", "set", port, "netns", self.switch)
        ip("link", "set", temp, "netns", name)
        ip("-n", name, "link", "set", temp, "name", "eth0")
        ip("-n", name, "addr", "add", f"{self.addresses[host]}/24", "dev", "eth0")
        ip("-n", name, "link", "set", "eth0", "up")
        ip("-n", self.switch, "link", "set", port, "master", "br0")
        ip("-n", self.switch, "link", "set", port, "up")

    def cable(self, host: str, up: bool) -> None:
        """Plug (``up``) or pull ``host``'s cable at the switch."""
        ip("-n", self.switch, "link", "set", self.port(host), "up" if up else "down")

    def command(self, host: str, argv: Sequence[str]) -> list[str]:
        """``argv`` run inside ``host``."""
        return ["ip", "netns", "exec", self.netns(host), *argv]

    def close(self) -> None:
        """Delete every namespace made (their interfaces and the bridge go with them)."""
        for name in reversed(self.made):
            ip("netns", "del", name, check=False)
        self.made.clear()
