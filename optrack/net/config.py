"""How a node joins the bus: the ``bus`` parameters and the Zenoh configuration they make.

Modes (``bus.mode``):

* ``local`` (default): one computer, loopback only. The tracker node hosts a
  Zenoh router on ``tcp/127.0.0.1:<local_port>``; every other node is a client
  of it. Nothing listens on, or scouts, any other interface.
* ``peer``: a real network. Nodes find each other by Zenoh's multicast
  scouting (``multicast_scouting``) and gossip, and/or the explicit
  ``connect`` endpoints; ``listen`` says where this node accepts links.
* ``client``: connect to the router(s) in ``connect`` (e.g. a ``zenohd``).
* ``router``: route for others, listening on ``listen``.

Every link is mutual TLS with the site's keys (``bus.keys``, made by
``optrack site init``; :mod:`optrack.net.security`), and Zenoh's access
control limits what each identity may send. A ``local`` site without
``bus.keys`` uses this user's own keys, made on first start; other modes
without keys refuse to start unless ``bus.insecure`` is on.

``zenoh_config`` names a Zenoh JSON5 file used as it is instead (namespaces,
other authentication...).
"""

from __future__ import annotations

import json
from pathlib import Path

import zenoh

from optrack.errors import UserError
from optrack.net.security import (
    CA_KEY_FILE,
    LOCAL_IDENTITY,
    OPERATOR_ROLES,
    SiteIdentities,
    access_control,
    local_keys,
    tls_settings,
)
from optrack.params import Param, Params, Schema, register

__all__ = [
    "BUS_PARAMS",
    "BusConfigError",
    "check_station",
    "endpoints",
    "site_identity",
    "zenoh_config",
]

BUS_PARAMS = register(
    Schema(
        "bus",
        [
            Param(
                "mode",
                "local",
                choices=("local", "peer", "client", "router"),
                help="local: this computer only (loopback); peer: a real network with "
                "scouting or endpoints; client/router: Zenoh client or router.",
            ),
            Param(
                "local_port",
                7447,
                min=1,
                max=65535,
                step=1,
                help="Loopback TCP port of the local site's hub (mode local).",
            ),
            Param(
                "listen",
                "",
                help="Comma-separated Zenoh endpoints to listen on (peer/router), e.g. "
                "tcp/0.0.0.0:7447; empty: Zenoh's default.",
            ),
            Param(
                "connect",
                "",
                help="Comma-separated Zenoh endpoints to connect to, e.g. tcp/192.168.1.10:7447.",
            ),
            Param(
                "multicast_scouting",
                True,
                help="Find other nodes by UDP multicast on the local network (peer/client).",
            ),
            Param("gossip", True, help="Let peers tell each other where they listen (peer)."),
            Param(
                "zenoh_config",
                "",
                help="Path of a Zenoh JSON5 configuration used as it is (overrides the rest).",
            ),
            Param(
                "keys",
                "",
                help="Folder of the site's keys ('optrack site init'): every link uses mutual "
                "TLS with them and each identity may send only what its role may; empty: a "
                "local site uses this user's own keys, other modes refuse to start.",
            ),
            Param(
                "identity",
                "",
                help="Whose certificate of bus.keys this process presents; empty: the node's "
                "name (an operator station names its own).",
            ),
            Param(
                "insecure",
                False,
                help="Let a peer/client/router node join without keys (no TLS, no access "
                "control: anyone on the network may speak); every status says so.",
            ),
            Param(
                "connect_timeout_s",
                10.0,
                min=0.0,
                max=600.0,
                step=0.5,
                unit="s",
                help="How long a node keeps trying to reach the bus when it starts.",
            ),
            Param(
                "max_message_bytes",
                4 * 1024 * 1024,
                min=1024,
                max=256 * 1024 * 1024,
                step=1024,
                unit="bytes",
                help="Larger received messages are refused (and counted).",
            ),
        ],
        help="The Zenoh bus: how nodes of a site find each other.",
    )
)


class BusConfigError(UserError):
    """A bus configuration that cannot work."""


def endpoints(text: str) -> list[str]:
    """Comma-separated endpoints as a list (blank entries dropped)."""
    items = [e.strip() for e in str(text).split(",") if e.strip()]
    for item in items:
        if "/" not in item:
            raise BusConfigError(
                f"bus endpoint '{item}' lacks a protocol; write it as tcp/HOST:PORT."
            )
    return items


#: Where a secured node listens when bus.listen is empty (Zenoh's defaults, over TLS).
DEFAULT_LISTEN = {"peer": "tls/[::]:0", "router": "tls/[::]:7447"}


def local_endpoint(params: Params) -> str:
    return f"tcp/127.0.0.1:{int(params.local_port)}"


def _set(config: zenoh.Config, key: str, value: object) -> None:
    config.insert_json5(key, json.dumps(value))


def _loopback(endpoint: str) -> bool:
    return endpoint.split("/", 1)[1].startswith(("127.", "localhost", "[::1]"))


def site_identity(params: Params, node: str = "") -> tuple[SiteIdentities, str] | None:
    """The keys and the identity this node presents, or None when it joins without
    (``bus.insecure`` on, in any mode but ``local``). A local site (or a client of a hub on
    this computer) without ``bus.keys`` uses this user's own keys, made on first start."""
    folder = str(params.keys).strip()
    if folder:
        identities = SiteIdentities(folder)
        return identities, identities.require(str(params.identity).strip() or node)
    mode = str(params.mode)
    if mode != "local" and bool(params.insecure):
        return None  # even to a hub on this computer: an insecure peer site's is plain tcp
    links = endpoints(str(params.listen)) + endpoints(str(params.connect))
    on_this_computer = mode == "local" or (
        mode == "client"
        and links
        and all(_loopback(e) for e in links)
        and not bool(params.multicast_scouting)
    )
    if on_this_computer:
        return SiteIdentities(local_keys()), LOCAL_IDENTITY
    raise BusConfigError(
        f"bus.mode {mode} without site keys would let anyone on the network join the site; "
        "make keys with 'optrack site init', copy them here and set bus.keys, or start with "
        "--insecure (bus.insecure) to run open."
    )


def check_station(params: Params, node: str) -> str:
    """What an operator station (a window, a tool named ``node``) lacks to join a site with
    these ``bus`` values, in one sentence naming the folder and the command: raised
    (:class:`BusConfigError`, :class:`~optrack.net.security.KeysError`) when it cannot
    join; returned when it can join but not operate (its identity is not a station's);
    "" when nothing lacks."""
    if params.zenoh_config:
        return ""
    folder = str(params.keys).strip()
    mode = str(params.mode)
    if not folder:
        try:
            site_identity(params, node)
        except BusConfigError:
            raise BusConfigError(
                f"joining a site over the network (bus.mode {mode}) needs the site's keys: "
                "copy the folder made by 'optrack site init --out FOLDER --stations NAME' to "
                "this computer and set bus.keys: FOLDER and bus.identity: NAME in the --config "
                "file (or bus.insecure: true to join a site started with --insecure)."
            ) from None
        return ""
    identities = SiteIdentities(folder)
    name = str(params.identity).strip()
    if not name and node not in identities.roles:
        stations = sorted(n for n, role in identities.roles.items() if role == "station")
        held = f"its stations: {', '.join(stations)}" if stations else "it holds no station"
        raise BusConfigError(
            f"bus.identity is empty: set it to this station's name in the site keys in "
            f"{identities.folder} ({held}), or add one with 'optrack site init --out "
            f"{identities.folder} --stations NAME' on the computer that holds {CA_KEY_FILE}."
        )
    role = identities.roles[identities.require(name or node)]
    if role in OPERATOR_ROLES:
        return ""
    return (
        f"bus.identity '{name or node}' is the {role}'s: this station sees the site, but the "
        "site's computers drop its parameter changes and commands; use a station's identity "
        f"('optrack site init --out {identities.folder} --stations NAME')."
    )


def _secured(items: list[str]) -> list[str]:
    """Endpoints with every ``tcp/`` link made a TLS one."""
    return [("tls/" + e[4:]) if e.startswith("tcp/") else e for e in items]


def zenoh_config(params: Params, *, host: bool = False, node: str = "") -> zenoh.Config:
    """The Zenoh configuration of node ``node``. ``host``: this node hosts a local site's
    hub. With keys (:func:`site_identity`) every link is mutual TLS and the site's access
    control applies."""
    if params.zenoh_config:
        path = Path(str(params.zenoh_config)).expanduser()
        if not path.is_file():
            raise BusConfigError(
                f"bus.zenoh_config {path} does not exist; fix the path or leave it empty."
            )
        try:
            return zenoh.Config.from_file(str(path))
        except zenoh.ZError as error:
            raise BusConfigError(
                f"bus.zenoh_config {path} is not a valid Zenoh file: {error}"
            ) from None
    config = zenoh.Config()
    mode = str(params.mode)
    listen = endpoints(str(params.listen))
    connect = endpoints(str(params.connect))
    multicast = bool(params.multicast_scouting)
    gossip = bool(params.gossip)
    if mode == "local":
        for endpoint in listen + connect:
            if not (endpoint.startswith("tcp/127.") or endpoint.startswith("tcp/localhost")):
                raise BusConfigError(
                    f"bus.mode local stays on this computer, but endpoint '{endpoint}' is not "
                    "loopback; use bus.mode peer for a real network."
                )
        if host:
            mode, listen, connect = "router", [local_endpoint(params)], []
        else:
            mode, listen, connect = "client", [], [local_endpoint(params)]
        multicast = gossip = False
    elif mode == "client" and not connect and not multicast:
        raise BusConfigError(
            "bus.mode client needs bus.connect endpoints (or bus.multicast_scouting on) to find "
            "a router."
        )
    identity = site_identity(params, node)
    if identity is not None:
        listen, connect = _secured(listen), _secured(connect)
        if not listen and mode in DEFAULT_LISTEN:
            listen = [DEFAULT_LISTEN[mode]]
        _set(config, "transport/link/tls", tls_settings(*identity))
        _set(config, "access_control", access_control(identity[0]))
    _set(config, "mode", mode)
    if listen or str(params.mode) == "local":
        _set(config, "listen/endpoints", listen)
    _set(config, "connect/endpoints", connect)
    _set(config, "scouting/multicast/enabled", multicast)
    _set(config, "scouting/gossip/enabled", gossip)
    if mode == "router":
        _set(config, "scouting/delay", 0)
    return config
