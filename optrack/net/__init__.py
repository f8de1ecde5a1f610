"""The bus: Zenoh sessions, wire messages and clock sync (docs/runtime.md)."""

from optrack.net.bus import Bus, BusError, MessageStats
from optrack.net.clock import CLOCK_PARAMS, ClockEstimate, ClockServer, ClockSync
from optrack.net.config import BUS_PARAMS, BusConfigError
from optrack.net.keys import SiteKeys
from optrack.net.messages import (
    WIRE_VERSION,
    CalibrationMessage,
    DetectionsMessage,
    MessageError,
    ParamsMessage,
    PreviewMessage,
    StatusMessage,
    TracksMessage,
    decode,
    encode,
)

__all__ = [
    "BUS_PARAMS",
    "CLOCK_PARAMS",
    "WIRE_VERSION",
    "Bus",
    "BusConfigError",
    "BusError",
    "CalibrationMessage",
    "ClockEstimate",
    "ClockServer",
    "ClockSync",
    "DetectionsMessage",
    "MessageError",
    "MessageStats",
    "ParamsMessage",
    "PreviewMessage",
    "SiteKeys",
    "StatusMessage",
    "TracksMessage",
    "decode",
    "encode",
]
