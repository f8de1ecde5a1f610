"""optrack: people tracking in networks of RGB-D cameras.

The core library (no Qt): shared types, geometry, parameter schemas,
recordings, readers for real data, and, as they land, the simulator,
detector, tracker, calibration and runtime. See docs/architecture.md.
"""

__version__ = "0.1.0"
