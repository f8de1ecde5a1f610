"""Where tracks go: OpenPTrack JSON over UDP, OSC, WebSocket (docs/runtime.md)."""

from optrack.outputs.streams import DEFAULT_UDP_PORT, OUTPUTS_PARAMS, Outputs
from optrack.outputs.udp import OutputError

__all__ = ["DEFAULT_UDP_PORT", "OUTPUTS_PARAMS", "OutputError", "Outputs"]
