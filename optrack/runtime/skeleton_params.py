"""The live skeleton stage's parameters (``skeleton_live``): on or off for the site, and
how people's points from every sensor meet their tracks (optrack/runtime/skeleton_node.py).

A module of its own, light to import, so that registering the stage never runs the node's
module twice (``python -m optrack.runtime.skeleton_node``)."""

from __future__ import annotations

from optrack.params import Param, Schema, register

__all__ = ["SKELETON_LIVE_PARAMS"]

SKELETON_LIVE_PARAMS = register(
    Schema(
        "skeleton_live",
        [
            Param(
                "enabled",
                False,
                help="Track skeletons: detector nodes publish each person's points and the "
                "skeleton node fits a body to them (optrack run --skeleton starts it).",
            ),
            Param(
                "stride",
                2,
                min=1,
                max=8,
                step=1,
                help="A detector node crops people from every this many depth pixels in rows "
                "and columns (the live skeleton_fusion.stride: 1 costs it about ten times "
                "the CPU of 2 for the same skeleton, the points being decimated to 2 cm).",
            ),
            Param(
                "gate_m",
                0.5,
                min=0.05,
                max=3.0,
                step=0.05,
                unit="m",
                help="A sensor's person belongs to the nearest track within this distance on "
                "the floor (else it is left out).",
            ),
            Param(
                "window_s",
                0.1,
                min=0.0,
                max=2.0,
                step=0.01,
                unit="s",
                help="A person's cloud fuses each sensor's newest points no older than this "
                "before the newest sensor's.",
            ),
            Param(
                "drop_after_s",
                1.0,
                min=0.1,
                max=60.0,
                step=0.1,
                unit="s",
                help="A skeleton whose track is gone, or has had no points, this long is dropped.",
            ),
            Param(
                "max_people",
                8,
                min=1,
                max=100,
                step=1,
                help="At most this many skeletons at once (the first tracks seen).",
            ),
        ],
        help="The live skeleton stage: on or off for the site, and how people's points "
        "from every sensor meet their tracks.",
    )
)
