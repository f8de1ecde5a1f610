"""Sensor URIs, the one way the CLI, config files and the GUI name a source of frames.

::

    file://<recording>[#sensor]     a recording played back (path relative or absolute)
    openni://<serial|URI|Dummy>     an OpenNI2 camera (empty: the first attached)
    realsense://<serial>            an Intel RealSense camera (empty: the first attached)
    sim://<scenario>/<n>            sensor n (0-based) of a simulated scenario

Any URI may end in ``?name=value&...``: ``id`` sets the sensor id, other
names set that backend's parameters (``openni://Dummy?color=false&fps=30``).
:func:`open_sensor` returns the sensor opened; a URI naming nothing
attached fails with one sentence that lists what is attached.

Each scheme is registered with :func:`register_scheme`: this module registers
the sources it has (``file``, ``openni``, ``realsense``); a source that lives
in a package above this one registers itself when imported, so this module
never imports it (``sim://`` comes with :mod:`optrack.sim.sensor`, which the
command line and the runtime import before they open a URI).
"""

from __future__ import annotations

import dataclasses
import urllib.parse
from collections.abc import Callable, Mapping
from typing import Any

from optrack.params import ParamError, Params, Schema
from optrack.recording import is_recording
from optrack.sensors.base import Sensor, SensorError

__all__ = [
    "Scheme",
    "SensorURI",
    "attached_summary",
    "open_sensor",
    "expected_sensor_id",
    "parse_uri",
    "register_scheme",
    "schemes",
]

_TRUE = {"1", "true", "yes", "on"}
_FALSE = {"0", "false", "no", "off"}


@dataclasses.dataclass(frozen=True)
class SensorURI:
    """A parsed sensor URI: ``scheme://target?query#fragment``."""

    scheme: str
    target: str
    query: tuple[tuple[str, str], ...] = ()
    fragment: str = ""
    text: str = ""

    @property
    def options(self) -> dict[str, str]:
        return dict(self.query)

    @property
    def sensor_id(self) -> str | None:
        return self.options.get("id") or None

    def __str__(self) -> str:
        return self.text


#: Opens a parsed URI with the stages' parameters (``config``, maybe empty).
Opener = Callable[[SensorURI, Mapping[str, Params]], Sensor]


@dataclasses.dataclass(frozen=True)
class Scheme:
    """A kind of source of frames: its URIs' scheme, how one is written (for messages)
    and what opens one."""

    name: str
    form: str
    open: Opener
    #: the id a URI's sensor will report, when it is known before the device opens
    identify: Callable[[SensorURI], str | None] | None = None


_SCHEMES: dict[str, Scheme] = {}


def register_scheme(
    name: str,
    form: str,
    opener: Opener,
    identify: Callable[[SensorURI], str | None] | None = None,
) -> None:
    """Open ``name://`` URIs with ``opener``; ``form`` shows how one is written, e.g.
    ``sim://SCENARIO/N``; ``identify`` (optional) tells the id a URI's sensor will report
    without opening it. Registering a name again replaces its opener."""
    _SCHEMES[name.lower()] = Scheme(name.lower(), form, opener, identify)


def expected_sensor_id(uri: str | SensorURI) -> str | None:
    """The id the sensor of ``uri`` will report: its ``?id=``, else what its scheme
    knows before opening it (a simulated venue's sensor), else its ``#fragment``
    (a recording's sensor); None when only the device can tell (a camera's serial)."""
    parsed = uri if isinstance(uri, SensorURI) else parse_uri(uri)
    if parsed.sensor_id:
        return parsed.sensor_id
    scheme = _SCHEMES.get(parsed.scheme)
    known = scheme.identify(parsed) if scheme is not None and scheme.identify else None
    return known or parsed.fragment or None


def schemes() -> tuple[str, ...]:
    """The schemes that open, in the order they were registered."""
    return tuple(_SCHEMES)


def _forms() -> str:
    forms = [scheme.form for scheme in _SCHEMES.values()]
    return ", ".join(forms[:-1]) + " or " + forms[-1] if len(forms) > 1 else "".join(forms)


def _scheme(name: str, text: str) -> Scheme:
    """The registered scheme ``name`` of the URI ``text``, or one sentence naming those
    that are."""
    scheme = _SCHEMES.get(name)
    if scheme is None:
        raise SensorError(
            f"sensor URI '{text}' has an unknown scheme '{name}'; use one of "
            + ", ".join(f"{s}://" for s in _SCHEMES)
            + "."
        )
    return scheme


def parse_uri(text: str) -> SensorURI:
    """Split a sensor URI; a bare path to a recording counts as ``file://``."""
    text = str(text).strip()
    scheme, sep, rest = text.partition("://")
    if not sep:
        if text and is_recording(text):
            return SensorURI("file", text, text=f"file://{text}")
        raise SensorError(f"'{text}' is not a sensor URI; use {_forms()}.")
    scheme = _scheme(scheme.lower(), text).name
    rest, _, fragment = rest.partition("#")
    target, _, query_text = rest.partition("?")
    try:
        query = tuple(
            urllib.parse.parse_qsl(query_text, keep_blank_values=True, strict_parsing=True)
        )
    except ValueError:
        query = ()
        if query_text:
            raise SensorError(
                f"sensor URI '{text}' has a malformed query '?{query_text}'; write "
                "?name=value&name=value."
            ) from None
    return SensorURI(scheme, urllib.parse.unquote(target), query, fragment, text)


def _convert(schema: Schema, name: str, value: str, uri: SensorURI) -> Any:
    if name not in schema:
        known = ", ".join(["id", *(p.name for p in schema)])
        raise SensorError(
            f"sensor URI '{uri}' sets '{name}', which {uri.scheme}:// does not have "
            f"(it has: {known})."
        )
    kind = schema[name].kind
    if kind is bool:
        if value.lower() in _TRUE:
            return True
        if value.lower() in _FALSE:
            return False
        raise SensorError(f"sensor URI '{uri}': {name} must be true or false; got '{value}'.")
    if kind in (int, float):
        try:
            number = float(value)
        except ValueError:
            raise SensorError(
                f"sensor URI '{uri}': {name} must be a number; got '{value}'."
            ) from None
        return int(number) if kind is int and number.is_integer() else number
    return value


def _params(schema: Schema, uri: SensorURI, base: Params | None) -> Params:
    params = schema.create(base.as_dict() if base is not None else None)
    updates = {
        name: _convert(schema, name, value, uri) for name, value in uri.query if name != "id"
    }
    try:
        params.update(updates)
    except ParamError as error:
        raise SensorError(f"sensor URI '{uri}': {error}") from None
    return params


def attached_summary() -> str:
    """ "attached: <model> (<uri>), ..." or "no depth camera is attached" (for messages)."""
    from optrack.sensors.usb import list_cameras

    try:
        cameras = list_cameras(read_serials=False)
    except SensorError as error:
        return f"cameras cannot be listed: {str(error).rstrip('.')}"
    if not cameras:
        return "no depth camera is attached"
    return "attached: " + ", ".join(f"{c.model} ({c.uri or 'not supported'})" for c in cameras)


def _open_file(uri: SensorURI, config: Mapping[str, Params]) -> Sensor:
    from optrack.sensors.playback import PLAYBACK_PARAMS, PlaybackSensor

    if not uri.target:
        raise SensorError(f"sensor URI '{uri}' names no recording; write file://PATH[#SENSOR].")
    params = _params(PLAYBACK_PARAMS, uri, config.get("playback"))
    return PlaybackSensor(
        uri.target, uri.fragment or None, params, uri=uri.text, sensor_id=uri.sensor_id
    )


def _open_openni(uri: SensorURI, config: Mapping[str, Params]) -> Sensor:
    from optrack.sensors.openni import OPENNI_PARAMS, OpenNISensor

    params = _params(OPENNI_PARAMS, uri, config.get("openni"))
    return OpenNISensor(uri.target, params, uri.sensor_id, uri=uri.text)


def _open_realsense(uri: SensorURI, config: Mapping[str, Params]) -> Sensor:
    from optrack.sensors.realsense import REALSENSE_PARAMS, RealSenseSensor

    params = _params(REALSENSE_PARAMS, uri, config.get("realsense"))
    return RealSenseSensor(uri.target, params, uri.sensor_id, uri=uri.text)


register_scheme("file", "file://RECORDING[#SENSOR]", _open_file)
register_scheme("openni", "openni://SERIAL (or openni://Dummy)", _open_openni)
register_scheme("realsense", "realsense://SERIAL", _open_realsense)


def open_sensor(uri: str | SensorURI, config: Mapping[str, Params] | None = None) -> Sensor:
    """The sensor a URI names, opened (close it, or use it in a ``with`` block).

    ``config`` maps stage names to parameters (as :func:`optrack.params.load_config`
    returns them); the URI's query overrides them.
    """
    parsed = uri if isinstance(uri, SensorURI) else parse_uri(uri)
    sensor = _scheme(parsed.scheme, parsed.text).open(parsed, config or {})
    sensor.open()
    return sensor
