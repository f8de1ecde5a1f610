"""How the window draws the site: the ``view`` parameters.

They change the picture only, never what a node computes, so they are not
part of the parameter presets sent to nodes (see docs/gui.md).
"""

from __future__ import annotations

from optrack.params import Param, Schema, register

__all__ = ["VIEW_PARAMS"]

VIEW_PARAMS = register(
    Schema(
        "view",
        [
            Param(
                "trail_seconds",
                8.0,
                min=0.0,
                max=120.0,
                step=0.5,
                unit="s",
                help="How much of each track's past path the top view and the 3D view draw.",
            ),
            Param(
                "track_radius",
                0.25,
                min=0.05,
                max=1.0,
                step=0.05,
                unit="m",
                help="Radius of the cylinder drawn for a person in the 3D view.",
            ),
            Param(
                "frustum_depth",
                0.6,
                min=0.1,
                max=5.0,
                step=0.1,
                unit="m",
                help="Length of the viewing pyramid drawn for each camera in the 3D view.",
            ),
            Param(
                "coverage_depth",
                5.0,
                min=0.5,
                max=50.0,
                step=0.5,
                unit="m",
                help="Range of a camera's floor footprint in the top view when the detector's "
                "max_distance is not known.",
            ),
            Param(
                "cloud_stride",
                4,
                min=1,
                max=16,
                step=1,
                help="The 3D view keeps every n-th preview pixel in rows and columns of each "
                "sensor's point cloud.",
            ),
            Param(
                "status_timeout",
                3.0,
                min=0.5,
                max=60.0,
                step=0.5,
                unit="s",
                help="A sensor whose node sends no status for this long is greyed out in the "
                "Sensors dock.",
            ),
            Param(
                "log_lines",
                2000,
                min=100,
                max=100000,
                step=100,
                help="The Log dock keeps this many most recent messages.",
            ),
            Param(
                "skeletons",
                True,
                help="Draw the people's skeletons in the 3D view (while the site's skeleton "
                "stage runs).",
            ),
        ],
        help="How the operator application draws the site (not sent to nodes).",
    )
)
