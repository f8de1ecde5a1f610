"""Capture: every source of RGB-D frames behind one interface, :class:`Sensor`.

Sources are named by URIs (see docs/architecture.md): ``sim://<scenario>/<n>``,
``file://<recording>[#sensor]``, ``openni://<serial or Dummy>``,
``realsense://<serial>``.
"""

from optrack.sensors.base import Sensor, SensorError
from optrack.sensors.uri import SensorURI, open_sensor, parse_uri

__all__ = ["Sensor", "SensorError", "SensorURI", "open_sensor", "parse_uri"]
