"""Sensor URIs, the one way the CLI, config files and the GUI name a source of frames.

::

    sim://<scenario>/<n>            sensor n (0-based) of a simulated scenario
    file://<recording>[#sensor]     a recording played back (path relative or absolute)
    openni://<serial|URI|Dummy>     an OpenNI2 camera (empty: the first attached)
    realsense://<serial>            an Intel RealSense camera (empty: the first attached)

Any URI may end in ``?name=value&...``: ``id`` sets the sensor id, other
names set that backend's parameters (``openni://Dummy?color=false&fps=30``).
:func:`open_sensor` returns the sensor opened; a URI naming nothing
attached fails with one sentence that lists what is attached.
"""

from __future__ import annotations

import dataclasses
import urllib.parse
from collections.abc import Mapping
from typing import Any

from optrack.params import ParamError, Params, Schema
from optrack.recording import is_recording
from optrack.sensors.base import Sensor, SensorError

__all__ = ["SCHEMES", "SensorURI", "attached_summary", "open_sensor", "parse_uri"]

SCHEMES = ("sim", "file", "openni", "realsense")
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


def parse_uri(text: str) -> SensorURI:
    """Split a sensor URI; a bare path to a recording counts as ``file://``."""
    text = str(text).strip()
    scheme, sep, rest = text.partition("://")
    if not sep:
        if text and is_recording(text):
            return SensorURI("file", text, text=f"file://{text}")
        raise SensorError(
            f"'{text}' is not a sensor URI; use sim://SCENARIO/N, file://RECORDING[#SENSOR], "
            "openni://SERIAL (or openni://Dummy) or realsense://SERIAL."
        )
    scheme = scheme.lower()
    if scheme not in SCHEMES:
        raise SensorError(
            f"sensor URI '{text}' has an unknown scheme '{scheme}'; use one of "
            + ", ".join(f"{s}://" for s in SCHEMES)
            + "."
        )
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


def _simulated(uri: SensorURI) -> Sensor:
    from optrack.sensors.simulated import SimulatedSensor

    return SimulatedSensor.from_uri(uri.text)


def _build(uri: SensorURI, config: Mapping[str, Params] | None) -> Sensor:
    config = config or {}
    if uri.scheme == "sim":
        return _simulated(uri)
    if uri.scheme == "file":
        from optrack.sensors.playback import PLAYBACK_PARAMS, PlaybackSensor

        if not uri.target:
            raise SensorError(f"sensor URI '{uri}' names no recording; write file://PATH[#SENSOR].")
        params = _params(PLAYBACK_PARAMS, uri, config.get("playback"))
        return PlaybackSensor(
            uri.target, uri.fragment or None, params, uri=uri.text, sensor_id=uri.sensor_id
        )
    if uri.scheme == "openni":
        from optrack.sensors.openni import OPENNI_PARAMS, OpenNISensor

        params = _params(OPENNI_PARAMS, uri, config.get("openni"))
        return OpenNISensor(uri.target, params, uri.sensor_id, uri=uri.text)
    from optrack.sensors.realsense import REALSENSE_PARAMS, RealSenseSensor

    params = _params(REALSENSE_PARAMS, uri, config.get("realsense"))
    return RealSenseSensor(uri.target, params, uri.sensor_id, uri=uri.text)


def open_sensor(uri: str | SensorURI, config: Mapping[str, Params] | None = None) -> Sensor:
    """The sensor a URI names, opened (close it, or use it in a ``with`` block).

    ``config`` maps stage names to parameters (as :func:`optrack.params.load_config`
    returns them); the URI's query overrides them.
    """
    parsed = uri if isinstance(uri, SensorURI) else parse_uri(uri)
    sensor = _build(parsed, config)
    sensor.open()
    return sensor
