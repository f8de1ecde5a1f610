"""Importing this module imports everything a detector, tracker or outputs node imports.

It is what the launcher's fork server loads once before it forks the nodes
(:mod:`optrack.runtime.starter`). The command line that starts a node,
``optrack.cli``, imports only the standard library and these.
"""

from __future__ import annotations

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
