"""The joints optrack names, shared by the body model, the simulator's truth and the outputs.

Names are lower-case with the side first (``left_wrist``); the tree is rooted at the
pelvis, as in MDCA's kinematic model. ``PARENT`` gives each joint's parent (the pelvis
has none), in an order where every parent comes before its children.
"""

from __future__ import annotations

PARENT: dict[str, str | None] = {
    "pelvis": None,
    "spine": "pelvis",
    "neck": "spine",
    "head": "neck",
    "left_shoulder": "neck",
    "left_elbow": "left_shoulder",
    "left_wrist": "left_elbow",
    "right_shoulder": "neck",
    "right_elbow": "right_shoulder",
    "right_wrist": "right_elbow",
    "left_hip": "pelvis",
    "left_knee": "left_hip",
    "left_ankle": "left_knee",
    "right_hip": "pelvis",
    "right_knee": "right_hip",
    "right_ankle": "right_knee",
}

JOINTS: tuple[str, ...] = tuple(PARENT)

# The paper's markers (Table I: RW, LW, RA, LA), scored by `optrack eval --skeleton`.
MARKERS: tuple[str, ...] = ("left_wrist", "right_wrist", "left_ankle", "right_ankle")
