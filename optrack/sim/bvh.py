"""BVH motion capture files: the reader, the skeleton's forward kinematics, joint names.

A BVH file (Biovision Hierarchy) holds a joint tree (``HIERARCHY``: each joint's
``OFFSET`` from its parent in the rest pose, its ``CHANNELS``, ``End Site`` tips)
and then ``MOTION``: ``Frames:``, ``Frame Time:`` and one line of channel values per
frame. Rotations are in degrees and compose in the order the channels are listed
(``Zrotation Yrotation Xrotation`` is ``R = Rz Ry Rx``); a joint's global pose is
``parent_global @ [R | offset]``, and the root's position channels add to its offset.
Line endings may be CRLF, LF or both; Euler angles may run past +-180 degrees.

BVH files are Y-up in file units. :data:`BVH_TO_WORLD` turns their axes into
optrack's world (z up): BVH (x, y, z) is world (z, x, y), so that the usual rest pose
(facing +Z, left +X, up +Y) faces +x with its left on +y, as optrack's body frame.
:func:`metres_per_unit` finds the unit from the rest figure's size.

Files name their joints in several conventions; :func:`map_joints` finds, for each
joint of :data:`optrack.skeleton.joints.JOINTS`, the BVH joint it is, and refuses an
unknown skeleton with one sentence listing its joints.
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
from pathlib import Path

import numpy as np

from optrack.errors import UserError
from optrack.sim.articulated import axis_rotations
from optrack.skeleton.joints import JOINTS

__all__ = [
    "BVH_TO_WORLD",
    "CMU_METRES_PER_UNIT",
    "BvhClip",
    "BvhJoint",
    "JointMap",
    "map_joints",
    "metres_per_unit",
    "read_bvh",
]

# BVH (x, y, z) -> world (z, x, y): a proper rotation (a cyclic permutation of the axes).
BVH_TO_WORLD = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])

# CMU's documented unit (1/0.45 inch), and the other units BVH files come in.
CMU_METRES_PER_UNIT = 0.0254 / 0.45
UNITS = (CMU_METRES_PER_UNIT, 0.0254, 0.01, 0.001, 1.0)
TYPICAL_FIGURE_M = 1.55  # rest-pose extent, lowest to highest point, of an adult figure
REFERENCE_JUMP_DEG = 5.0  # frame 0 is a reference pose if it differs this much from frame 1

_AXES = {"X": 0, "Y": 1, "Z": 2}


@dataclasses.dataclass(frozen=True)
class BvhJoint:
    """One joint of the BVH tree: its parent's index (-1 for the root), its rest offset
    from the parent (file units, BVH axes), its channels and its End Site's offset."""

    name: str
    parent: int
    offset: np.ndarray
    channels: tuple[str, ...]
    end_site: np.ndarray | None = None


@dataclasses.dataclass
class BvhClip:
    """A BVH file: its joint tree and its frames of channel values."""

    path: str
    joints: list[BvhJoint]
    frames: np.ndarray  # (F, channels)
    frame_time: float

    @property
    def names(self) -> list[str]:
        return [j.name for j in self.joints]

    @property
    def frame_count(self) -> int:
        return len(self.frames)

    @property
    def duration(self) -> float:
        return self.frame_count * self.frame_time

    def index(self, name: str) -> int:
        return self.names.index(name)

    def _columns(self) -> list[int]:
        starts, column = [], 0
        for joint in self.joints:
            starts.append(column)
            column += len(joint.channels)
        return starts

    def local(self, frames: np.ndarray | slice | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Local rotations (F, J, 3, 3) and translations (F, J, 3) of every joint (file
        units, BVH axes); ``frames`` selects frames (default all)."""
        values = self.frames if frames is None else self.frames[frames]
        values = np.atleast_2d(values)
        count = len(values)
        rotations = np.broadcast_to(np.eye(3), (count, len(self.joints), 3, 3)).copy()
        translations = np.empty((count, len(self.joints), 3))
        for j, (joint, start) in enumerate(zip(self.joints, self._columns(), strict=True)):
            translations[:, j] = joint.offset
            for k, channel in enumerate(joint.channels):
                column = values[:, start + k]
                axis = _AXES[channel[0].upper()]
                if channel[1:].lower() == "position":
                    translations[:, j, axis] += column
                else:
                    rotations[:, j] = rotations[:, j] @ axis_rotations(axis, np.radians(column))
        return rotations, translations

    def forward_kinematics(
        self, frames: np.ndarray | slice | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Global joint positions (F, J, 3) and rotations (F, J, 3, 3), file units and
        BVH axes; ``frames`` selects frames (default all)."""
        local_r, local_t = self.local(frames)
        positions = np.empty_like(local_t)
        rotations = np.empty_like(local_r)
        for j, joint in enumerate(self.joints):
            if joint.parent < 0:
                positions[:, j], rotations[:, j] = local_t[:, j], local_r[:, j]
            else:
                parent_r = rotations[:, joint.parent]
                positions[:, j] = positions[:, joint.parent] + np.einsum(
                    "fij,fj->fi", parent_r, local_t[:, j]
                )
                rotations[:, j] = parent_r @ local_r[:, j]
        return positions, rotations

    def end_sites(self, positions: np.ndarray, rotations: np.ndarray) -> dict[int, np.ndarray]:
        """Global positions (F, 3) of the End Sites, by the index of the joint they end."""
        return {
            j: positions[:, j] + rotations[:, j] @ joint.end_site
            for j, joint in enumerate(self.joints)
            if joint.end_site is not None
        }

    def rest_positions(self) -> np.ndarray:
        """Joint positions (J, 3) in the rest pose (every channel zero), BVH axes."""
        positions = np.zeros((len(self.joints), 3))
        for j, joint in enumerate(self.joints):
            positions[j] = joint.offset + (positions[joint.parent] if joint.parent >= 0 else 0.0)
        return positions

    def starts_with_reference_pose(self) -> bool:
        """Whether frame 0 is a reference pose (CMU takes: round values, far from frame 1)."""
        if self.frame_count < 2:
            return False
        rotation = np.array(
            [
                start + k
                for joint, start in zip(self.joints, self._columns(), strict=True)
                for k, channel in enumerate(joint.channels)
                if channel.lower().endswith("rotation")
            ],
            dtype=int,
        )
        first, second = self.frames[0, rotation], self.frames[1, rotation]
        jump = np.abs((second - first + 180.0) % 360.0 - 180.0)
        return bool(np.all(first == np.round(first)) and jump.max() > REFERENCE_JUMP_DEG)


# ------------------------------------------------------------------ reading


class _Tokens:
    """The hierarchy's tokens with their line numbers, for the parser's messages."""

    def __init__(self, path: str, lines: list[str]) -> None:
        self.path = path
        self.items = [(word, n + 1) for n, line in enumerate(lines) for word in line.split()]
        self.at = 0

    def next(self, expected: str = "") -> str:
        if self.at >= len(self.items):
            raise UserError(
                f"BVH file {self.path} ends inside its HIERARCHY; it is truncated, give a whole file."
            )
        word, line = self.items[self.at]
        self.at += 1
        if expected and word.upper() != expected.upper():
            raise UserError(
                f"BVH file {self.path} is malformed at line {line} ('{word}' where '{expected}' "
                "belongs); fix the file or export it again."
            )
        return word

    def number(self) -> float:
        word = self.next()
        try:
            return float(word)
        except ValueError:
            line = self.items[self.at - 1][1]
            raise UserError(
                f"BVH file {self.path} is malformed at line {line} ('{word}' where a number "
                "belongs); fix the file or export it again."
            ) from None


def _parse_joint(tokens: _Tokens, name: str, parent: int, joints: list[BvhJoint]) -> None:
    tokens.next("{")
    tokens.next("OFFSET")
    offset = np.array([tokens.number() for _ in range(3)])
    channels: tuple[str, ...] = ()
    index = len(joints)
    joints.append(BvhJoint(name, parent, offset, channels))
    end_site = None
    while True:
        word = tokens.next()
        upper = word.upper()
        if upper == "CHANNELS":
            count = int(tokens.number())
            channels = tuple(tokens.next() for _ in range(count))
            bad = [c for c in channels if not re.fullmatch(r"[XYZxyz](position|rotation)", c, re.I)]
            if bad:
                raise UserError(
                    f"BVH file {tokens.path}: joint {name} has an unknown channel '{bad[0]}' "
                    "(BVH channels are X/Y/Z position and rotation); fix the file."
                )
        elif upper == "JOINT":
            _parse_joint(tokens, tokens.next(), index, joints)
        elif upper == "END":
            tokens.next("Site")
            tokens.next("{")
            tokens.next("OFFSET")
            end_site = np.array([tokens.number() for _ in range(3)])
            tokens.next("}")
        elif upper == "}":
            break
        else:
            line = tokens.items[tokens.at - 1][1]
            raise UserError(
                f"BVH file {tokens.path} is malformed at line {line} (unexpected '{word}' in "
                f"joint {name}); fix the file or export it again."
            )
    joints[index] = BvhJoint(name, parent, offset, channels, end_site)


def read_bvh(path: str | os.PathLike[str]) -> BvhClip:
    """Read a BVH file (any mix of CRLF and LF line endings)."""
    name = os.fspath(path)
    try:
        text = Path(name).read_text(encoding="utf-8", errors="replace")
    except FileNotFoundError:
        raise UserError(f"BVH file {name} does not exist; check the path.") from None
    except OSError as error:
        raise UserError(f"BVH file {name} cannot be read ({error.strerror}).") from None
    text = text.replace("\r\n", "\n").replace("\r", "\n")
    head, found, motion = text.partition("\nMOTION")
    if not head.lstrip().upper().startswith("HIERARCHY") or not found:
        raise UserError(
            f"{name} is not a BVH file (it must start with HIERARCHY and hold MOTION); "
            "give a .bvh motion capture file."
        )
    tokens = _Tokens(name, head.split("\n"))
    tokens.next("HIERARCHY")
    tokens.next("ROOT")
    joints: list[BvhJoint] = []
    _parse_joint(tokens, tokens.next(), -1, joints)
    match = re.match(
        r"\s*Frames:\s*(\d+)\s*Frame\s+Time:\s*([-+0-9.eE]+)\s*(.*)\Z", motion, re.S | re.I
    )
    if match is None:
        raise UserError(
            f"BVH file {name}: MOTION must be followed by 'Frames: N' and 'Frame Time: T'; "
            "fix the file."
        )
    count, frame_time = int(match.group(1)), float(match.group(2))
    width = sum(len(j.channels) for j in joints)
    try:
        values = np.array(match.group(3).split(), dtype=np.float64)
    except ValueError:
        raise UserError(
            f"BVH file {name} has a frame value that is not a number; fix the file."
        ) from None
    if len(values) < count * width or not (frame_time > 0 and math.isfinite(frame_time)):
        raise UserError(
            f"BVH file {name} says {count} frames of {width} values every {frame_time:g} s but "
            f"holds {len(values) // max(width, 1)} whole frames; it is truncated or damaged."
        )
    frames = values[: count * width].reshape(count, width)
    return BvhClip(name, joints, frames, frame_time)


def metres_per_unit(clip: BvhClip) -> float:
    """The file's unit in metres: the one among CMU's (1/0.45 inch), inch, centimetre,
    millimetre and metre that makes the rest figure's extent nearest an adult's."""
    positions = clip.rest_positions()
    tips = [
        positions[j] + joint.end_site
        for j, joint in enumerate(clip.joints)
        if joint.end_site is not None
    ]
    points = np.concatenate([positions, np.reshape(tips, (-1, 3))])
    extent = float(np.ptp(points[:, 1]))  # Y is up
    if extent <= 0:
        raise UserError(f"BVH file {clip.path} has a flat rest skeleton; it cannot be a figure.")
    return min(UNITS, key=lambda unit: abs(math.log(extent * unit / TYPICAL_FIGURE_M)))


# ------------------------------------------------------------ joint names

# Each convention: for every joint of ours, the BVH names it may carry (lower case, any
# namespace such as "mixamorig:" removed, the first present wins), and the names that
# must be present for the convention to apply. Tried in order.
_LEFT_RIGHT = ("left", "right")


def _sided(pattern: dict[str, tuple[str, ...]]) -> dict[str, tuple[str, ...]]:
    out = {}
    for name, options in pattern.items():
        for side in _LEFT_RIGHT:
            short = side[0]
            out[f"{side}_{name}"] = tuple(o.format(side=side, s=short) for o in options)
    return out


# CMU's and Mixamo's limbs: LeftArm is the shoulder (LeftShoulder the collar bone).
_UPLEG_LIMBS = _sided(
    {
        "shoulder": ("{side}arm",),
        "elbow": ("{side}forearm",),
        "wrist": ("{side}hand",),
        "hip": ("{side}upleg",),
        "knee": ("{side}leg",),
        "ankle": ("{side}foot",),
    }
)

CONVENTIONS: tuple[tuple[str, frozenset[str], dict[str, tuple[str, ...]]], ...] = (
    (
        "CMU (LeftUpLeg/LeftLeg/LeftFoot)",
        frozenset({"lowerback", "leftupleg"}),
        {"pelvis": ("hips",), "spine": ("spine",), "neck": ("neck",), "head": ("head",)}
        | _UPLEG_LIMBS,
    ),
    (
        "Mixamo (mixamorig:LeftUpLeg, Spine1, Spine2)",
        frozenset({"spine2", "leftupleg"}),
        {"pelvis": ("hips",), "spine": ("spine1",), "neck": ("neck",), "head": ("head",)}
        | _UPLEG_LIMBS,
    ),
    (
        "LeftHip/LeftKnee/LeftAnkle",
        frozenset({"leftknee"}),
        {
            "pelvis": ("hips", "hip", "pelvis", "root"),
            "spine": ("chest", "spine", "spine1", "abdomen"),
            "neck": ("lowerneck", "neck"),
            "head": ("head",),
        }
        | _sided(
            {
                "shoulder": ("{side}shoulder", "{side}uparm", "{side}upperarm"),
                "elbow": ("{side}elbow", "{side}lowarm", "{side}forearm"),
                "wrist": ("{side}wrist", "{side}hand"),
                "hip": ("{side}hip", "{side}upleg", "{side}thigh"),
                "knee": ("{side}knee",),
                "ankle": ("{side}ankle", "{side}foot"),
            }
        ),
    ),
    (
        "3ds Max Biped (Bip01 L Thigh)",
        frozenset({"l thigh", "l calf"}),
        {"pelvis": ("pelvis",), "spine": ("spine1", "spine"), "neck": ("neck",), "head": ("head",)}
        | _sided(
            {
                "shoulder": ("{s} upperarm",),
                "elbow": ("{s} forearm",),
                "wrist": ("{s} hand",),
                "hip": ("{s} thigh",),
                "knee": ("{s} calf",),
                "ankle": ("{s} foot",),
            }
        ),
    ),
)

# The BVH joints that tip the hands and feet (the head's tip is its End Site).
_TIP_NAMES = {
    "hand": ("{side}handindex1", "{side}handmiddle1", "{s}fingers", "{s} finger2"),
    "toe": ("{side}toebase", "{side}toe", "{s} toe0"),
}


def _key(name: str) -> str:
    """A BVH joint name as the conventions spell it: lower case, namespace removed."""
    key = name.rsplit(":", 1)[-1].strip().lower()
    return re.sub(r"^bip0*1\s+", "", key).replace("_", "")


@dataclasses.dataclass(frozen=True)
class JointMap:
    """Which BVH joint each of our joints is (indices into the clip's joints), and the
    tips: BVH joint indices of the hands' and feet's tips (or -1) by side."""

    convention: str
    joints: dict[str, int]
    hand_tips: dict[str, int]
    toe_tips: dict[str, int]


def map_joints(clip: BvhClip) -> JointMap:
    """The BVH joint of each joint in JOINTS; an unknown skeleton is a UserError."""
    keys: dict[str, int] = {}
    for i, joint in enumerate(clip.joints):
        keys.setdefault(_key(joint.name), i)
    for convention, required, table in CONVENTIONS:
        if not required <= keys.keys():
            continue
        found = {}
        for ours, options in table.items():
            present = [keys[o] for o in options if o in keys]
            if not present:
                break
            found[ours] = present[0]
        else:
            assert set(found) == set(JOINTS)
            tips: dict[str, dict[str, int]] = {"hand": {}, "toe": {}}
            for part, options in _TIP_NAMES.items():
                for side in _LEFT_RIGHT:
                    names = [o.format(side=side, s=side[0]) for o in options]
                    present = [keys[n] for n in names if n in keys]
                    tips[part][side] = present[0] if present else -1
            return JointMap(convention, found, tips["hand"], tips["toe"])
    listed = ", ".join(clip.names)
    raise UserError(
        f"BVH file {clip.path} has a skeleton optrack does not know (its joints: {listed}); "
        "name them as CMU (LeftUpLeg, LeftLeg, LeftFoot), Mixamo or LeftHip/LeftKnee/LeftAnkle "
        "files do."
    )
