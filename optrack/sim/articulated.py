"""Articulated bodies: a joint-angle state and its forward kinematics.

A body is a tree of joints (:data:`BODY_JOINTS`: optrack's :data:`~optrack.skeleton.joints.JOINTS`
and the tips the mesh needs: chin, hands, toes). Its state (:class:`ArticulatedPose`) is
the pelvis's position in the world and every joint's rotation relative to its parent
(the pelvis's relative to the world), as 3x3 matrices. In the rest pose every rotation
is the identity: the body stands straight in its own frame (x forward, y left, z up),
arms hanging, feet flat. A person's shape is their bones' rest offsets (each joint's
position relative to its parent in the rest pose), so that
``position[j] = position[parent] + global[parent] @ offset[j]`` and
``global[j] = global[parent] @ local[j]``. Everything is vectorised over people.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial.transform import Rotation

from optrack.skeleton.joints import JOINTS, PARENT

__all__ = [
    "BODY_JOINTS",
    "BODY_PARENTS",
    "TIPS",
    "ArticulatedPose",
    "axis_rotations",
    "blend",
    "forward_kinematics",
    "frame_from",
    "rotation_vectors",
    "swing",
]

# The mesh's tips, beyond optrack's joints: each with its parent joint.
TIPS: dict[str, str] = {
    "chin": "head",
    "left_hand": "left_wrist",
    "right_hand": "right_wrist",
    "left_toe": "left_ankle",
    "right_toe": "right_ankle",
}
BODY_JOINTS: tuple[str, ...] = JOINTS + tuple(TIPS)
BODY_PARENTS = np.array(
    [
        -1
        if PARENT.get(name, TIPS.get(name)) is None
        else BODY_JOINTS.index(PARENT.get(name) or TIPS[name])
        for name in BODY_JOINTS
    ]
)


@dataclasses.dataclass
class ArticulatedPose:
    """The joint-angle state of P bodies: ``root`` (P, 3) is the pelvis in the world,
    ``local`` (P, len(BODY_JOINTS), 3, 3) each joint's rotation relative to its parent
    (the pelvis's: relative to the world). Identity rotations are the rest pose."""

    root: np.ndarray
    local: np.ndarray

    @classmethod
    def rest(cls, count: int) -> ArticulatedPose:
        return cls(
            np.zeros((count, 3)), np.broadcast_to(np.eye(3), (count, len(BODY_JOINTS), 3, 3)).copy()
        )

    def angles(self) -> np.ndarray:
        """(P, joints, 3) rotation vectors (axis times angle, radians) of ``local``."""
        return rotation_vectors(self.local)


def forward_kinematics(offsets: np.ndarray, pose: ArticulatedPose) -> tuple[np.ndarray, np.ndarray]:
    """World positions (P, J, 3) and global rotations (P, J, 3, 3) of every joint, for
    rest ``offsets`` (P, J, 3) (the pelvis's is unused: its position is ``pose.root``)."""
    local = pose.local
    positions = np.empty(local.shape[:-1])
    rotations = np.empty_like(local)
    positions[:, 0] = pose.root
    rotations[:, 0] = local[:, 0]
    for j in range(1, len(BODY_JOINTS)):
        parent = BODY_PARENTS[j]
        rotations[:, j] = rotations[:, parent] @ local[:, j]
        positions[:, j] = positions[:, parent] + np.einsum(
            "pij,pj->pi", rotations[:, parent], offsets[:, j]
        )
    return positions, rotations


def axis_rotations(axis: int, angles: np.ndarray) -> np.ndarray:
    """Rotations (n, 3, 3) by ``angles`` (n,) radians about axis 0 (x), 1 (y) or 2 (z)."""
    angles = np.asarray(angles, dtype=np.float64).reshape(-1)
    c, s = np.cos(angles), np.sin(angles)
    out = np.zeros((len(angles), 3, 3))
    i, k = (axis + 1) % 3, (axis + 2) % 3  # cyclic: the rotation turns i towards k
    out[:, axis, axis] = 1.0
    out[:, i, i], out[:, k, k] = c, c
    out[:, i, k], out[:, k, i] = -s, s
    return out


def swing(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotations (..., 3, 3) taking directions ``a`` to ``b`` (..., 3); a half
    turn about an axis perpendicular to ``a`` where they are opposite."""
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    axis = np.cross(a, b)
    sin = np.linalg.norm(axis, axis=-1)
    cos = np.sum(a * b, axis=-1)
    angle = np.arctan2(sin, cos)
    # Opposite directions: any axis perpendicular to a.
    other = np.where(np.abs(a[..., :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    fallback = np.cross(a, other)
    axis = np.where((sin < 1e-9)[..., None], fallback, axis)
    axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
    shape = axis.shape
    flat = Rotation.from_rotvec((axis * angle[..., None]).reshape(-1, 3)).as_matrix()
    return flat.reshape(*shape[:-1], 3, 3)


def frame_from(
    primary: np.ndarray, secondary: np.ndarray, primary_axis: int, secondary_axis: int
) -> np.ndarray:
    """Rotations (..., 3, 3) whose column ``primary_axis`` is along ``primary`` and whose
    column ``secondary_axis`` is ``secondary`` made perpendicular to it (right-handed)."""
    first = primary / np.linalg.norm(primary, axis=-1, keepdims=True)
    second = secondary - np.sum(secondary * first, axis=-1, keepdims=True) * first
    second /= np.linalg.norm(second, axis=-1, keepdims=True)
    third = np.cross(first, second)
    columns: list[np.ndarray | None] = [None, None, None]
    columns[primary_axis], columns[secondary_axis] = first, second
    last = 3 - primary_axis - secondary_axis
    # A right-handed frame: x = y cross z, y = z cross x, z = x cross y.
    sign = 1.0 if (secondary_axis - primary_axis) % 3 == 1 else -1.0
    columns[last] = sign * third
    return np.stack(columns, axis=-1)


def rotation_vectors(rotations: np.ndarray) -> np.ndarray:
    """Rotation vectors (..., 3) of rotation matrices (..., 3, 3)."""
    shape = rotations.shape[:-2]
    return Rotation.from_matrix(rotations.reshape(-1, 3, 3)).as_rotvec().reshape(*shape, 3)


def quaternions(rotations: np.ndarray) -> np.ndarray:
    """Unit quaternions (..., 4), (x, y, z, w), of rotation matrices (..., 3, 3)."""
    shape = rotations.shape[:-2]
    return Rotation.from_matrix(rotations.reshape(-1, 3, 3)).as_quat().reshape(*shape, 4)


def matrices(quats: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of quaternions (..., 4), normalised first."""
    shape = quats.shape[:-1]
    return Rotation.from_quat(quats.reshape(-1, 4)).as_matrix().reshape(*shape, 3, 3)


def blend(first: np.ndarray, second: np.ndarray, weight: float | np.ndarray) -> np.ndarray:
    """Quaternions (..., 4) between ``first`` (weight 0) and ``second`` (weight 1), by
    normalised linear interpolation on the shorter arc."""
    weight = np.asarray(weight, dtype=np.float64)[..., None] if np.ndim(weight) else weight
    sign = np.where(np.sum(first * second, axis=-1, keepdims=True) < 0.0, -1.0, 1.0)
    mixed = (1.0 - weight) * first + weight * sign * second
    return mixed / np.linalg.norm(mixed, axis=-1, keepdims=True)
