"""MDCA's body model: the kinematic tree, joint limits, forward kinematics, the shape.

Kinematic tree (MDCA §III): the pelvis is the root with a 6-DOF global pose
(position, then yaw about z, pitch about y, roll about x); the torso has R6
(spine 3, neck 3), each arm R4 (shoulder 3, elbow 1) and each leg R4 (hip 3,
knee 1): 22 joint angles after the root, so a state is a vector of
``D = 28`` numbers (metres and radians; :data:`DOFS` names them).

Frames: the body frame is x forward, y left, z up; in the rest pose (all
zeros but the root) the person stands upright with the arms hanging and the
legs straight. A 3-DOF joint turns by ``R_flex @ R_abduction @ R_twist``
about the axes of :data:`DOFS`; the right side's abduction and twist axes are
mirrored, so a positive angle means the same motion on both sides.

Shape (MDCA eq. 2-5, the extended cylinder): each body part is a cylinder
along a bone, extended past its joints (``t0 < 0`` or ``t1 > 1``, in bone
lengths) and closed by ellipsoidal caps; its cross-section is an ellipse
whose forward radius varies linearly along the bone (``radius_start`` at the
bone's start, ``radius_end`` at its end) and whose side radius is the
forward radius times ``aspect``. A point's scaled distance to a part is
measured in units of the local radius (see optrack/skeleton/likelihood.py).

Proportions are fractions of the standing height from Drillis and Contini's
anthropometric table (D. A. Winter, *Biomechanics and Motor Control of Human
Movement*, 4th ed., fig. 4.1): ankle 0.039 H, knee 0.285 H, hip 0.530 H,
shoulder 0.818 H, upper arm 0.186 H, forearm 0.146 H, shoulder width 0.259 H,
hip width 0.191 H.
"""

from __future__ import annotations

import dataclasses
import functools

import numba
import numpy as np

from optrack.skeleton.joints import JOINTS

__all__ = [
    "D",
    "DOFS",
    "FRAMES",
    "G",
    "GEOMETRY_FIELDS",
    "LIMITS",
    "PARTITIONS",
    "PARTS",
    "PART_INDEX",
    "POINTS",
    "BodyShape",
    "Part",
    "forward_kinematics",
    "bone_lengths",
    "part_areas",
    "part_reach",
    "part_geometry",
    "rest_state",
    "surface_points",
]

# ---------------------------------------------------------------- the state
# (name, frame it turns, axis in the parent frame, lower limit, upper limit); radians.
_X, _Y, _Z = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)
_NX, _NY, _NZ = (-1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, -1.0)
_INF = np.inf


def _limb(side: str, root: str, mid: str, sign: float, flex_axis, mid_axis, lim) -> list:
    abd = _X if sign > 0 else _NX
    twist = _Z if sign > 0 else _NZ
    return [
        (f"{side}_{root}_flex", f"{side}_{root}", flex_axis, *lim[0]),
        (f"{side}_{root}_abduction", f"{side}_{root}", abd, *lim[1]),
        (f"{side}_{root}_twist", f"{side}_{root}", twist, *lim[2]),
        (f"{side}_{mid}_flex", f"{side}_{mid}", mid_axis, *lim[3]),
    ]


_ARM_LIMITS = ((-1.0, 3.1), (-0.6, 3.0), (-1.5, 1.5), (0.0, 2.6))
_LEG_LIMITS = ((-0.6, 2.3), (-0.5, 1.2), (-0.9, 0.9), (0.0, 2.6))

_DOF_TABLE: list[tuple] = [
    ("root_x", "pelvis", None, -_INF, _INF),
    ("root_y", "pelvis", None, -_INF, _INF),
    ("root_z", "pelvis", None, 0.2, 2.0),
    ("root_yaw", "pelvis", _Z, -_INF, _INF),
    ("root_pitch", "pelvis", _Y, -1.0, 1.0),
    ("root_roll", "pelvis", _X, -0.7, 0.7),
    ("spine_flex", "spine", _Y, -0.5, 1.6),
    ("spine_lateral", "spine", _X, -0.6, 0.6),
    ("spine_twist", "spine", _Z, -0.8, 0.8),
    ("neck_flex", "neck", _Y, -0.8, 1.0),
    ("neck_lateral", "neck", _X, -0.6, 0.6),
    ("neck_twist", "neck", _Z, -1.2, 1.2),
    *_limb("left", "shoulder", "elbow", 1.0, _NY, _NY, _ARM_LIMITS),
    *_limb("right", "shoulder", "elbow", -1.0, _NY, _NY, _ARM_LIMITS),
    *_limb("left", "hip", "knee", 1.0, _NY, _Y, _LEG_LIMITS),
    *_limb("right", "hip", "knee", -1.0, _NY, _Y, _LEG_LIMITS),
]
DOFS: tuple[str, ...] = tuple(row[0] for row in _DOF_TABLE)
D = len(DOFS)
LIMITS = np.array([(row[3], row[4]) for row in _DOF_TABLE])  # (D, 2)
_ANGLE_DOFS = [i for i, row in enumerate(_DOF_TABLE) if row[2] is not None]

# The five partitions of partitioned sampling, in MDCA's order: torso first, then the limbs.
PARTITIONS: dict[str, tuple[int, ...]] = {
    "torso": tuple(range(12)),
    "left_arm": tuple(range(12, 16)),
    "right_arm": tuple(range(16, 20)),
    "left_leg": tuple(range(20, 24)),
    "right_leg": tuple(range(24, 28)),
}

# ---------------------------------------------------------------- the frames
# Each turning joint's frame and the frame it hangs from: the shoulders hang from the
# chest (the spine's frame), so that turning the head does not move the arms.
FRAMES: tuple[str, ...] = (
    "pelvis",
    "spine",
    "neck",
    "left_shoulder",
    "left_elbow",
    "right_shoulder",
    "right_elbow",
    "left_hip",
    "left_knee",
    "right_hip",
    "right_knee",
)
_FRAME_PARENT = {
    "pelvis": None,
    "spine": "pelvis",
    "neck": "spine",
    "left_shoulder": "spine",
    "left_elbow": "left_shoulder",
    "right_shoulder": "spine",
    "right_elbow": "right_shoulder",
    "left_hip": "pelvis",
    "left_knee": "left_hip",
    "right_hip": "pelvis",
    "right_knee": "right_hip",
}
# Each frame's angles in the order they compose (the root: Rz(yaw) Ry(pitch) Rx(roll)).
_FRAME_DOFS = {name: [i for i in _ANGLE_DOFS if _DOF_TABLE[i][1] == name] for name in FRAMES}

# Points the model places: the joints, then each foot's toe (which only the shape uses).
POINTS: tuple[str, ...] = (*JOINTS, "left_toe", "right_toe")
# (point, the point it hangs from, the frame its offset turns with)
_POINT_TABLE: tuple[tuple[str, str | None, str], ...] = (
    ("pelvis", None, "pelvis"),
    ("spine", "pelvis", "pelvis"),
    ("neck", "spine", "spine"),
    ("head", "neck", "neck"),
    ("left_shoulder", "neck", "spine"),
    ("left_elbow", "left_shoulder", "left_shoulder"),
    ("left_wrist", "left_elbow", "left_elbow"),
    ("right_shoulder", "neck", "spine"),
    ("right_elbow", "right_shoulder", "right_shoulder"),
    ("right_wrist", "right_elbow", "right_elbow"),
    ("left_hip", "pelvis", "pelvis"),
    ("left_knee", "left_hip", "left_hip"),
    ("left_ankle", "left_knee", "left_knee"),
    ("right_hip", "pelvis", "pelvis"),
    ("right_knee", "right_hip", "right_hip"),
    ("right_ankle", "right_knee", "right_knee"),
    ("left_toe", "left_ankle", "left_knee"),
    ("right_toe", "right_ankle", "right_knee"),
)
assert tuple(row[0] for row in _POINT_TABLE) == POINTS
_PI = {name: i for i, name in enumerate(POINTS)}
_FI = {name: i for i, name in enumerate(FRAMES)}


# ---------------------------------------------------------------- the shape
@dataclasses.dataclass(frozen=True)
class Part:
    """One extended cylinder along the bone from point ``a`` to point ``b`` (eq. 2-5)."""

    name: str
    a: str
    b: str
    frame: str  # the frame whose x axis is the cross-section's forward radius
    t0: float  # where the cylinder starts and ends, in bone lengths from a
    t1: float
    radius_start: float  # forward radius at a and at b, fractions of the height
    radius_end: float
    aspect: float  # side radius / forward radius
    partition: str


def _limb_parts(side: str) -> tuple[Part, ...]:
    s = side
    return (
        Part(f"{s}_upper_arm", f"{s}_shoulder", f"{s}_elbow", f"{s}_shoulder", -0.05, 1.0,
             0.027, 0.022, 1.0, f"{s}_arm"),
        Part(f"{s}_forearm", f"{s}_elbow", f"{s}_wrist", f"{s}_elbow", 0.0, 1.45,
             0.021, 0.017, 1.0, f"{s}_arm"),
    )  # fmt: skip


def _leg_parts(side: str) -> tuple[Part, ...]:
    s = side
    return (
        Part(f"{s}_thigh", f"{s}_hip", f"{s}_knee", f"{s}_hip", 0.0, 1.0,
             0.048, 0.034, 1.0, f"{s}_leg"),
        Part(f"{s}_shin", f"{s}_knee", f"{s}_ankle", f"{s}_knee", 0.0, 1.0,
             0.032, 0.022, 1.0, f"{s}_leg"),
        Part(f"{s}_foot", f"{s}_ankle", f"{s}_toe", f"{s}_knee", -0.15, 1.0,
             0.022, 0.022, 1.0, f"{s}_leg"),
    )  # fmt: skip


PARTS: tuple[Part, ...] = (
    Part("lower_trunk", "pelvis", "spine", "pelvis", -0.35, 1.0, 0.058, 0.056, 1.6, "torso"),
    Part("upper_trunk", "spine", "neck", "spine", 0.0, 1.0, 0.056, 0.06, 1.6, "torso"),
    Part("head", "neck", "head", "neck", 0.45, 1.05, 0.056, 0.056, 0.85, "torso"),
    *_limb_parts("left"),
    *_limb_parts("right"),
    *_leg_parts("left"),
    *_leg_parts("right"),
)
PART_INDEX = {part.name: k for k, part in enumerate(PARTS)}


@dataclasses.dataclass(frozen=True)
class BodyShape:
    """One person's limb lengths and radii, metres (see :meth:`from_height`)."""

    height: float
    lower_trunk: float  # pelvis to spine
    upper_trunk: float  # spine to neck (shoulder height)
    head: float  # neck to the head's centre
    shoulder_half_width: float
    hip_half_width: float
    upper_arm: float
    forearm: float
    thigh: float
    shin: float
    foot: float  # ankle to toe, forward
    foot_drop: float  # the toe sits this far below the ankle
    radii: tuple[tuple[float, float], ...]  # per part of PARTS: forward radius at a, at b

    @classmethod
    def from_height(cls, height: float) -> BodyShape:
        """The average person of this standing height (Winter's fractions)."""
        h = float(height)
        trunk = (0.818 - 0.530) / 2 * h
        return cls(
            height=h,
            lower_trunk=trunk,
            upper_trunk=trunk,
            head=(0.935 - 0.818) * h,
            shoulder_half_width=0.259 / 2 * 0.8 * h,
            hip_half_width=0.191 / 2 * 0.55 * h,
            upper_arm=0.186 * h,
            forearm=0.146 * h,
            thigh=(0.530 - 0.285) * h,
            shin=(0.285 - 0.039) * h,
            foot=0.11 * h,
            foot_drop=0.02 * h,
            radii=tuple((p.radius_start * h, p.radius_end * h) for p in PARTS),
        )

    def scaled(
        self,
        *,
        arms: float = 1.0,
        legs: float = 1.0,
        trunk: float = 1.0,
        width: float = 1.0,
        limb_radius: float = 1.0,
        trunk_radius: float = 1.0,
    ) -> BodyShape:
        """This shape with some proportions multiplied (the shape estimate's search space)."""
        radii = tuple(
            (r0 * (trunk_radius if p.partition == "torso" else limb_radius),
             r1 * (trunk_radius if p.partition == "torso" else limb_radius))
            for p, (r0, r1) in zip(PARTS, self.radii, strict=True)
        )  # fmt: skip
        return dataclasses.replace(
            self,
            lower_trunk=self.lower_trunk * trunk,
            upper_trunk=self.upper_trunk * trunk,
            shoulder_half_width=self.shoulder_half_width * width,
            hip_half_width=self.hip_half_width * width,
            upper_arm=self.upper_arm * arms,
            forearm=self.forearm * arms,
            thigh=self.thigh * legs,
            shin=self.shin * legs,
            radii=radii,
        )

    @property
    def standing_pelvis_height(self) -> float:
        """Pelvis height of this person standing straight, feet on the floor."""
        return self.ankle_height + self.thigh + self.shin

    @property
    def ankle_height(self) -> float:
        return 0.039 * self.height

    def offsets(self) -> np.ndarray:
        """Each point's offset from the point it hangs from, in its frame, (len(POINTS), 3)."""
        return self._offsets.copy()

    @functools.cached_property
    def radii_array(self) -> np.ndarray:
        """:attr:`radii` as a (K, 2) array (what the kernels read)."""
        return np.asarray(self.radii, dtype=np.float64)

    @functools.cached_property
    def _offsets(self) -> np.ndarray:
        o = {
            "pelvis": (0.0, 0.0, 0.0),
            "spine": (0.0, 0.0, self.lower_trunk),
            "neck": (0.0, 0.0, self.upper_trunk),
            "head": (0.0, 0.0, self.head),
            "left_shoulder": (0.0, self.shoulder_half_width, 0.0),
            "right_shoulder": (0.0, -self.shoulder_half_width, 0.0),
            "left_hip": (0.0, self.hip_half_width, 0.0),
            "right_hip": (0.0, -self.hip_half_width, 0.0),
        }
        for side in ("left", "right"):
            o[f"{side}_elbow"] = (0.0, 0.0, -self.upper_arm)
            o[f"{side}_wrist"] = (0.0, 0.0, -self.forearm)
            o[f"{side}_knee"] = (0.0, 0.0, -self.thigh)
            o[f"{side}_ankle"] = (0.0, 0.0, -self.shin)
            o[f"{side}_toe"] = (self.foot, 0.0, -self.foot_drop)
        return np.array([o[name] for name in POINTS], dtype=np.float64)


def rest_state(shape: BodyShape, x: float = 0.0, y: float = 0.0, yaw: float = 0.0) -> np.ndarray:
    """The state of this person standing straight at (x, y) facing ``yaw``, (D,)."""
    state = np.zeros(D)
    state[0], state[1], state[2], state[3] = x, y, shape.standing_pelvis_height, yaw
    return state


# ---------------------------------------------------------------- kinematics
# The tables the kernels read: per frame its parent and up to three (dof, axis, sign);
# per point the point it hangs from and its frame.
_FRAME_PARENT_I = np.array(
    [-1 if _FRAME_PARENT[f] is None else _FI[_FRAME_PARENT[f]] for f in FRAMES]
)
_FRAME_DOF_I = np.full((len(FRAMES), 3), -1)
_FRAME_AXIS_I = np.zeros((len(FRAMES), 3), dtype=np.int64)
_FRAME_SIGN = np.zeros((len(FRAMES), 3))
for _f, _name in enumerate(FRAMES):
    for _j, _d in enumerate(_FRAME_DOFS[_name]):
        _axis = _DOF_TABLE[_d][2]
        _FRAME_DOF_I[_f, _j] = _d
        _FRAME_AXIS_I[_f, _j] = int(np.argmax(np.abs(_axis)))
        _FRAME_SIGN[_f, _j] = _axis[_FRAME_AXIS_I[_f, _j]]
_POINT_PARENT_I = np.array([-1 if row[1] is None else _PI[row[1]] for row in _POINT_TABLE])
_POINT_FRAME_I = np.array([_FI[row[2]] for row in _POINT_TABLE])


@numba.njit(cache=True, fastmath=True)
def fk_pose(
    x, cos_x, sin_x, offsets, chosen, rot, pts, fparent, fdof, faxis, fsign, pparent, pframe
):
    """One pose: fill rot (F, 3, 3) and pts (Q, 3) for the chosen frames and their points
    (the others are read as they are there); x, cos_x, sin_x (D,)."""
    for f in range(fparent.shape[0]):
        if not chosen[f]:
            continue
        q = fparent[f]
        for r in range(3):
            for c in range(3):
                rot[f, r, c] = rot[q, r, c] if q >= 0 else (1.0 if r == c else 0.0)
        for j in range(3):  # R <- R @ (rotation about axis k by the dof's angle)
            d = fdof[f, j]
            if d < 0:
                break
            k = faxis[f, j]
            i, m = (k + 1) % 3, (k + 2) % 3
            cos, sin = cos_x[d], sin_x[d] * fsign[f, j]
            for r in range(3):
                ri, rm = rot[f, r, i], rot[f, r, m]
                rot[f, r, i] = cos * ri + sin * rm
                rot[f, r, m] = cos * rm - sin * ri
    for n in range(pparent.shape[0]):
        f = pframe[n]
        if not chosen[f]:
            continue
        q = pparent[n]
        for r in range(3):
            if q < 0:
                pts[n, r] = x[r]
            else:
                pts[n, r] = pts[q, r] + (
                    rot[f, r, 0] * offsets[n, 0]
                    + rot[f, r, 1] * offsets[n, 1]
                    + rot[f, r, 2] * offsets[n, 2]
                )


@numba.njit(cache=True, fastmath=True)
def _fk_kernel(x, cos_x, sin_x, offsets, chosen, rot, pts, *tables):
    for p in range(x.shape[0]):
        fk_pose(x[p], cos_x[p], sin_x[p], offsets, chosen, rot[p], pts[p], *tables)


# The kinematic tables in the order fk_pose reads them (after pts).
FK_TABLES = (
    _FRAME_PARENT_I, _FRAME_DOF_I, _FRAME_AXIS_I, _FRAME_SIGN, _POINT_PARENT_I, _POINT_FRAME_I,
)  # fmt: skip


def forward_kinematics(
    state: np.ndarray,
    shape: BodyShape,
    frames: tuple[str, ...] = FRAMES,
    base: tuple[np.ndarray, np.ndarray] | None = None,
    out: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """World positions of :data:`POINTS` and rotations of :data:`FRAMES` for many states.

    ``state`` is (P, D) or (D,); returns points (P, len(POINTS), 3) and frames
    (P, len(FRAMES), 3, 3) (without the leading P for a single state). With
    ``frames`` a subset (a limb's chain) and ``base`` the (points, frames) of one
    full pose, only that subset is recomputed; the rest is copied from ``base``.
    ``out``: arrays of those shapes to write into instead (what ``frames`` does not
    turn is left as it is there: a buffer filled with a base once serves many calls).
    """
    single = np.ndim(state) == 1
    x = np.atleast_2d(np.asarray(state, dtype=np.float64))
    n = len(x)
    if out is not None:
        points, rotations = out
    elif base is None:
        points = np.empty((n, len(POINTS), 3))
        rotations = np.empty((n, len(FRAMES), 3, 3))
    else:
        points = np.broadcast_to(base[0], (n, len(POINTS), 3)).copy()
        rotations = np.broadcast_to(base[1], (n, len(FRAMES), 3, 3)).copy()
    chosen = np.array([name in frames for name in FRAMES])
    # Sines and cosines of the angles that turn the chosen frames only (float32: numpy's
    # fast path; they place points to well under a micrometre).
    angles = [d for name in frames for d in _FRAME_DOFS[name]]
    cos_x, sin_x = np.empty((n, D), np.float32), np.empty((n, D), np.float32)
    turned = x[:, angles].astype(np.float32)
    cos_x[:, angles], sin_x[:, angles] = np.cos(turned), np.sin(turned)
    _fk_kernel(x, cos_x, sin_x, shape._offsets, chosen, rotations, points, *FK_TABLES)
    if single:
        return points[0], rotations[0]
    return points, rotations


# Indices the part geometry needs, as arrays.
_PART_A = np.array([_PI[p.a] for p in PARTS])
_PART_B = np.array([_PI[p.b] for p in PARTS])
_PART_FRAME = np.array([_FI[p.frame] for p in PARTS])
_PART_T = np.array([(p.t0, p.t1) for p in PARTS])
_PART_ASPECT = np.array([p.aspect for p in PARTS])

# Layout of one part's row in the table the likelihood reads.
GEOMETRY_FIELDS = (
    "ax", "ay", "az", "ux", "uy", "uz", "ex", "ey", "ez", "fx", "fy", "fz",
    "s0", "s1", "r0", "dr", "inv_length",
)  # fmt: skip
G = len(GEOMETRY_FIELDS)


@numba.njit(cache=True, fastmath=True)
def geometry_pose(pts, rot, parts, pa, pb, pf, pt, aspect, radii, out):
    """One pose's rows of :func:`part_geometry`: pts (Q, 3), rot (F, 3, 3), out (len(parts), G)."""
    for j in range(parts.shape[0]):
        k = parts[j]
        a, b, f = pa[k], pb[k], pf[k]
        u0 = pts[b, 0] - pts[a, 0]
        u1 = pts[b, 1] - pts[a, 1]
        u2 = pts[b, 2] - pts[a, 2]
        length = max(np.sqrt(u0 * u0 + u1 * u1 + u2 * u2), 1e-9)
        u0, u1, u2 = u0 / length, u1 / length, u2 / length
        # The forward axis: the frame's x made square to the bone (its y if parallel).
        c = 0 if abs(rot[f, 0, 0] * u0 + rot[f, 1, 0] * u1 + rot[f, 2, 0] * u2) < 0.999 else 1
        dot = rot[f, 0, c] * u0 + rot[f, 1, c] * u1 + rot[f, 2, c] * u2
        e0 = rot[f, 0, c] - dot * u0
        e1 = rot[f, 1, c] - dot * u1
        e2 = rot[f, 2, c] - dot * u2
        en = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
        e0, e1, e2 = e0 / en, e1 / en, e2 / en
        w = 1.0 / aspect[k]
        row = out[j]
        row[0], row[1], row[2] = pts[a, 0], pts[a, 1], pts[a, 2]
        row[3], row[4], row[5] = u0, u1, u2
        row[6], row[7], row[8] = e0, e1, e2
        row[9] = (u1 * e2 - u2 * e1) * w
        row[10] = (u2 * e0 - u0 * e2) * w
        row[11] = (u0 * e1 - u1 * e0) * w
        row[12], row[13] = pt[k, 0] * length, pt[k, 1] * length
        row[14], row[15] = radii[k, 0], radii[k, 1] - radii[k, 0]
        row[16] = 1.0 / length


@numba.njit(cache=True, fastmath=True)
def _geometry_kernel(pts, rot, parts, pa, pb, pf, pt, aspect, radii, out):
    for p in range(pts.shape[0]):
        geometry_pose(pts[p], rot[p], parts, pa, pb, pf, pt, aspect, radii, out[p])


# The part tables in the order geometry_pose reads them (after parts).
PART_TABLES = (_PART_A, _PART_B, _PART_FRAME, _PART_T, _PART_ASPECT)


def part_geometry(
    points: np.ndarray, rotations: np.ndarray, shape: BodyShape, parts: np.ndarray | None = None
) -> np.ndarray:
    """Each part's cylinder, as the likelihood reads it: (P, K, G) float32.

    Per part: the start joint ``a``; the unit bone direction ``u``; the forward
    cross-section axis ``e``; the side axis ``f`` divided by ``aspect`` (so that
    the scaled radial distance is a plain norm); the cylinder's extent ``s0..s1``
    along ``u`` in metres; the forward radius ``r0`` at ``a`` and its change
    ``dr`` to ``b``; and 1 / bone length. ``parts`` selects some parts (indices).
    """
    k = np.arange(len(PARTS)) if parts is None else np.asarray(parts, dtype=np.int64)
    out = np.empty((len(points), len(k), G), dtype=np.float32)
    _geometry_kernel(points, rotations, k, *PART_TABLES, shape.radii_array, out)
    return out


def bone_lengths(shape: BodyShape) -> np.ndarray:
    """Each part's bone length (from its point a to its point b), m, (K,)."""
    return np.linalg.norm(shape.offsets(), axis=1)[_PART_B]


def part_reach(shape: BodyShape, parts: np.ndarray) -> float:
    """How far a chain of parts reaches from its first joint, m (bones and extensions)."""
    return float(np.sum(bone_lengths(shape)[parts] * _PART_T[parts, 1]))


def part_areas(shape: BodyShape) -> np.ndarray:
    """Each part's lateral surface, m^2 (mean perimeter of its ellipse times its extent)."""
    length = bone_lengths(shape)
    radii = np.asarray(shape.radii).mean(axis=1)
    side = radii * _PART_ASPECT
    perimeter = np.pi * (radii + side)
    return perimeter * length * (_PART_T[:, 1] - _PART_T[:, 0])


def _cap_areas(shape: BodyShape) -> np.ndarray:
    """Each part's two end caps (half ellipsoids of radii r, r * aspect, r), m^2, (K, 2):
    Thomsen's approximation of an ellipsoid's surface, halved."""
    r = np.asarray(shape.radii)
    side = r * _PART_ASPECT[:, None]
    q = 1.6
    return 2.0 * np.pi * ((2.0 * (r * side) ** q + r ** (2 * q)) / 3.0) ** (1.0 / q)


def surface_points(
    state: np.ndarray, shape: BodyShape, count: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Points spread evenly over the model's surface (sides and end caps) at one state,
    and their outward normals, each (count, 3): what a perfect sensor all around sees."""
    points, rotations = forward_kinematics(np.asarray(state, dtype=np.float64), shape)
    geometry = part_geometry(points[None], rotations[None], shape)[0].astype(np.float64)
    # Pieces: each part's side, its start cap, its end cap.
    areas = np.concatenate([part_areas(shape)[:, None], _cap_areas(shape)], axis=1).ravel()
    piece = rng.choice(areas.size, size=count, p=areas / areas.sum())
    g, kind = geometry[piece // 3], piece % 3
    e, f = g[:, 6:9], g[:, 9:12]
    f_unit = f / np.linalg.norm(f, axis=1, keepdims=True)
    angle = rng.uniform(0.0, 2.0 * np.pi, count)
    # Along the bone: uniform on the side; at the cap's base for a cap, then pushed out.
    s = np.where(kind == 0, g[:, 12] + rng.uniform(size=count) * (g[:, 13] - g[:, 12]), 0.0)
    s = np.where(kind == 1, g[:, 12], np.where(kind == 2, g[:, 13], s))
    cos_polar = np.where(kind == 0, 0.0, rng.uniform(size=count))  # uniform on a sphere
    sin_polar = np.sqrt(1.0 - cos_polar**2)
    outward = np.where(kind == 1, -1.0, 1.0) * cos_polar
    r = g[:, 14] + g[:, 15] * np.clip(s * g[:, 16], 0.0, 1.0)
    side = r / np.linalg.norm(f, axis=1)  # the side radius, r * aspect
    across_e, across_f = np.cos(angle) * sin_polar, np.sin(angle) * sin_polar
    surface = (
        g[:, 0:3]
        + (s + r * outward)[:, None] * g[:, 3:6]
        + (r * across_e)[:, None] * e
        + (side * across_f)[:, None] * f_unit
    )
    # The outward normal: the gradient of (x/r)^2 + (y/side)^2 + (z/r)^2.
    normal = (
        (across_e / r)[:, None] * e
        + (across_f / side)[:, None] * f_unit
        + (outward / r)[:, None] * g[:, 3:6]
    )
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    return surface, normal
