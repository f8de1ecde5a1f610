"""Humanoid bodies: each person's shape, the walking gait as joint angles, and the mesh.

A body is 15 parts (head, neck, torso, upper arms, forearms, hands, thighs,
shins, feet) in the spirit of MDCA's extended-cylinder shape model: each
limb is an elliptic cylinder (or, for varied shapes, an elliptic frustum:
limbs taper) between two joints, the head an ellipsoid. The parts hang on the
joint tree of :mod:`optrack.sim.articulated` and are posed by its joint-angle
state through forward kinematics; each part's cross-section turns with the
joint at its base.

Segment lengths and radii are fractions of the standing height ``H`` from
the anthropometric table of Drillis and Contini as given in D. A. Winter,
*Biomechanics and Motor Control of Human Movement* (4th ed., Wiley 2009),
figure 4.1: ankle 0.039 H, knee 0.285 H, hip 0.530 H, shoulder 0.818 H,
chin 0.870 H, upper arm 0.186 H, forearm 0.146 H, hand 0.108 H, foot
0.152 H, shoulder width 0.259 H, hip width 0.191 H. A *standard* shape is
exactly that, with straight cylinders; a *varied* shape draws each segment's
length and each part's girth, ellipticity and taper per person (keeping the
height), so that no two people share a shape.

Everything is vectorised over people: ``P`` people give ``(P, J, 3)``
joints and one concatenated mesh. The body frame is x forward, y left, z up,
origin on the floor under the pelvis.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import open3d as o3d

from optrack.params import Param, Schema, register
from optrack.sim.articulated import (
    BODY_JOINTS,
    BODY_PARENTS,
    ArticulatedPose,
    axis_rotations,
    forward_kinematics,
    rotation_vectors,
    swing,
)
from optrack.skeleton.joints import JOINTS as SKELETON_JOINTS

__all__ = [
    "BODY_PARAMS",
    "JOINTS",
    "PART_NAMES",
    "TRUTH_JOINTS",
    "BodyModel",
    "BodyPose",
    "BodyShape",
    "BodyState",
]

BODY_PARAMS = register(
    Schema(
        "sim_body",
        [
            Param(
                "hip_swing_deg",
                24.0,
                0,
                60,
                1,
                "deg",
                "Thigh swing amplitude at full walking speed.",
            ),
            Param("knee_swing_deg", 55.0, 0, 90, 1, "deg", "Knee flexion peak in the swing phase."),
            Param(
                "knee_stance_deg", 6.0, 0, 30, 1, "deg", "Knee flexion while standing on the leg."
            ),
            Param("arm_swing_deg", 20.0, 0, 60, 1, "deg", "Arm swing amplitude at full speed."),
            Param("elbow_deg", 15.0, 0, 90, 1, "deg", "Elbow flexion at rest."),
            Param(
                "elbow_swing_deg",
                15.0,
                0,
                60,
                1,
                "deg",
                "Extra elbow flexion when the arm swings forward.",
            ),
            Param(
                "arm_abduction_deg",
                6.0,
                0,
                45,
                1,
                "deg",
                "How far the arms hang away from the body.",
            ),
            Param(
                "stride_per_height",
                0.8,
                0.3,
                1.5,
                0.05,
                "",
                "Stride length (two steps) as a fraction of height.",
            ),
            Param(
                "full_gait_speed",
                1.3,
                0.3,
                3.0,
                0.1,
                "m/s",
                "Speed at which the gait reaches full amplitude.",
            ),
            Param("sway_m", 0.015, 0, 0.1, 0.005, "m", "Sideways sway of a standing person."),
            Param("limb_segments", 6, 4, 32, 1, "", "Facets around each limb cylinder."),
            Param("head_resolution", 5, 3, 20, 1, "", "Resolution of the head ellipsoid mesh."),
            Param(
                "length_spread",
                0.05,
                0.0,
                0.2,
                0.01,
                "",
                "Varied shapes: relative spread (sigma) of each segment's length.",
            ),
            Param(
                "radius_spread",
                0.12,
                0.0,
                0.4,
                0.01,
                "",
                "Varied shapes: relative spread (sigma) of girth and of each part's radii.",
            ),
        ],
        help="The simulated people's body shape and walking gait.",
    )
)

JOINTS = BODY_JOINTS  # every joint of a body, optrack's first, then the mesh's tips
TRUTH_JOINTS = SKELETON_JOINTS
J = {name: i for i, name in enumerate(JOINTS)}

# Anthropometric fractions of height (Winter 2009, fig. 4.1).
ANKLE_Z, KNEE_Z, HIP_Z, SHOULDER_Z, CHIN_Z = 0.039, 0.285, 0.530, 0.818, 0.870
UPPER_ARM, FOREARM, HAND, FOOT = 0.186, 0.146, 0.108, 0.152
SHOULDER_HALF_WIDTH = 0.259 / 2 * 0.8  # joint centres sit inside the outer width
HIP_HALF_WIDTH = 0.191 / 2 * 0.55
HEAD_CENTER_Z, HEAD_RADII = 0.935, (0.057, 0.045, 0.065)  # forward, side, up
TOE_FORWARD = 0.11  # ankle to toe, along the foot
TOE_LIFT = 0.02  # the toe sits this fraction of H below the ankle
THIGH = HIP_Z - KNEE_Z
SHIN = KNEE_Z - ANKLE_Z
HAND_REACH = 0.8  # the hand segment ends at this share of the hand length

MAX_GAIT_AMPLITUDE = 1.2  # a brisk walk swings a little more than a normal one

# Rest offsets (fractions of H) of each joint from its parent, and the segment each
# belongs to (the length a varied shape draws per person).
_REST: dict[str, tuple[tuple[float, float, float], str]] = {
    "pelvis": ((0.0, 0.0, 0.0), "foot"),  # its height: the ankle's, plus the leg
    "spine": ((0.0, 0.0, (SHOULDER_Z - HIP_Z) / 2), "torso"),
    "neck": ((0.0, 0.0, (SHOULDER_Z - HIP_Z) / 2), "torso"),
    "head": ((0.0, 0.0, HEAD_CENTER_Z - SHOULDER_Z), "head"),
    "left_shoulder": ((0.0, SHOULDER_HALF_WIDTH, 0.0), "shoulders"),
    "left_elbow": ((0.0, 0.0, -UPPER_ARM), "upper_arm"),
    "left_wrist": ((0.0, 0.0, -FOREARM), "forearm"),
    "left_hip": ((0.0, HIP_HALF_WIDTH, 0.0), "hips"),
    "left_knee": ((0.0, 0.0, -THIGH), "thigh"),
    "left_ankle": ((0.0, 0.0, -SHIN), "shin"),
    "chin": ((0.0, 0.0, CHIN_Z - HEAD_CENTER_Z), "head"),
    "left_hand": ((0.0, 0.0, -HAND * HAND_REACH), "hand"),
    "left_toe": ((TOE_FORWARD, 0.0, -TOE_LIFT), "foot"),
}
SEGMENTS = tuple(sorted({segment for _, segment in _REST.values()}))

# Materials of a person, in this order in the material table.
SKIN, HAIR, SHIRT, TROUSERS, SHOES = range(5)
MATERIALS_PER_PERSON = 5


@dataclasses.dataclass(frozen=True)
class Part:
    name: str
    a: str  # joint at the cylinder's base (or the ellipsoid's centre)
    b: str | None  # joint at its top; None for an ellipsoid
    radii: tuple[float, float]  # fractions of H: along the reference direction, across it
    material: int
    reference: str = "forward"  # the base joint's axis the first radius is aligned with
    taper: float = 1.0  # varied shapes: radii at the top over radii at the base


PARTS = (
    Part("head", "head", None, HEAD_RADII[:2], SKIN),
    Part("neck", "neck", "chin", (0.028, 0.03), SKIN),
    Part("torso", "pelvis", "neck", (0.06, 0.095), SHIRT, taper=1.08),
    Part("left_upper_arm", "left_shoulder", "left_elbow", (0.025, 0.025), SHIRT, taper=0.82),
    Part("left_forearm", "left_elbow", "left_wrist", (0.021, 0.021), SHIRT, taper=0.72),
    Part("left_hand", "left_wrist", "left_hand", (0.012, 0.024), SKIN),
    Part("right_upper_arm", "right_shoulder", "right_elbow", (0.025, 0.025), SHIRT, taper=0.82),
    Part("right_forearm", "right_elbow", "right_wrist", (0.021, 0.021), SHIRT, taper=0.72),
    Part("right_hand", "right_wrist", "right_hand", (0.012, 0.024), SKIN),
    Part("left_thigh", "left_hip", "left_knee", (0.045, 0.045), TROUSERS, taper=0.7),
    Part("left_shin", "left_knee", "left_ankle", (0.03, 0.03), TROUSERS, taper=0.72),
    Part("left_foot", "left_ankle", "left_toe", (0.02, 0.025), SHOES, "up"),
    Part("right_thigh", "right_hip", "right_knee", (0.045, 0.045), TROUSERS, taper=0.7),
    Part("right_shin", "right_knee", "right_ankle", (0.03, 0.03), TROUSERS, taper=0.72),
    Part("right_foot", "right_ankle", "right_toe", (0.02, 0.025), SHOES, "up"),
)
CYLINDERS = tuple(p for p in PARTS if p.b is not None)
PART_NAMES = tuple(p.name for p in PARTS)  # a per-pixel part label indexes this


@dataclasses.dataclass(frozen=True)
class BodyShape:
    """One person's shape: bones' rest offsets (len(JOINTS), 3), metres, body frame (the
    pelvis's is its standing height above the floor); each limb's radii (len(CYLINDERS),
    4): along its reference axis and across it, at its base then at its top; the head's
    radii (forward, side, up); the ankle's and toe's heights when standing."""

    height: float
    offsets: np.ndarray
    radii: np.ndarray
    head: np.ndarray

    @property
    def ankle_height(self) -> float:
        return float(
            self.offsets[J["pelvis"], 2]
            + self.offsets[J["left_knee"], 2]
            + self.offsets[J["left_ankle"], 2]
        )

    @property
    def toe_height(self) -> float:
        return self.ankle_height + float(self.offsets[J["left_toe"], 2])

    @property
    def leg_length(self) -> float:
        """Hip to knee to ankle, metres (the mean of both legs)."""
        return float(
            np.mean(
                [
                    np.linalg.norm(self.offsets[J[f"{s}_knee"]])
                    + np.linalg.norm(self.offsets[J[f"{s}_ankle"]])
                    for s in ("left", "right")
                ]
            )
        )

    @classmethod
    def standard(cls, height: float) -> BodyShape:
        """Winter's proportions, straight cylinders."""
        return cls._build(
            height, dict.fromkeys(SEGMENTS, 1.0), np.ones((len(CYLINDERS), 4)), np.ones(3)
        )

    @classmethod
    def varied(
        cls, height: float, rng: np.random.Generator, length_spread: float, radius_spread: float
    ) -> BodyShape:
        """A shape of its own: every segment's length, the body's girth and each part's
        radii, ellipticity and taper drawn around Winter's, the height kept."""

        def factor(spread: float, size: int | None = None) -> np.ndarray:
            return np.clip(rng.normal(1.0, spread, size), 1.0 - 2.5 * spread, 1.0 + 2.5 * spread)

        lengths = {segment: float(factor(length_spread)) for segment in SEGMENTS}
        girth = float(factor(radius_spread))
        base = girth * factor(radius_spread / 2, len(CYLINDERS))
        elliptic = factor(radius_spread / 2, len(CYLINDERS))
        taper = np.array([p.taper for p in CYLINDERS]) * factor(radius_spread / 2, len(CYLINDERS))
        scale = np.stack(
            [base * elliptic, base / elliptic, base * elliptic * taper, base / elliptic * taper],
            axis=1,
        )
        return cls._build(height, lengths, scale, girth * factor(radius_spread / 3, 3))

    @classmethod
    def _build(
        cls,
        height: float,
        lengths: dict[str, float],
        radii_scale: np.ndarray,
        head_scale: np.ndarray,
    ) -> BodyShape:
        offsets = np.zeros((len(JOINTS), 3))
        for name, (offset, segment) in _REST.items():
            for side, sign in (
                (("left", 1.0), ("right", -1.0)) if name.startswith("left_") else (("", 0.0),)
            ):
                target = name.replace("left", side, 1) if side else name
                mirrored = (offset[0], offset[1] * (sign if side else 1.0), offset[2])
                offsets[J[target]] = np.array(mirrored) * lengths[segment]
        head = np.array(HEAD_RADII) * head_scale
        # Keep the standing height: floor to the top of the head.
        offsets[J["pelvis"], 2] = (
            ANKLE_Z * lengths["foot"] - offsets[J["left_knee"], 2] - offsets[J["left_ankle"], 2]
        )
        stature = offsets[[J["pelvis"], J["spine"], J["neck"], J["head"]], 2].sum() + head[2]
        scale = height / stature
        radii = np.array([[*p.radii, *p.radii] for p in CYLINDERS]) * radii_scale
        return cls(float(height), offsets * scale, radii * scale, head * scale)


@dataclasses.dataclass
class BodyPose:
    """What a walking body needs at one instant, for P people (arrays of length P)."""

    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray  # radians, the direction the body faces
    height: np.ndarray  # standing height, m
    phase: np.ndarray  # gait phase, radians
    amplitude: np.ndarray  # gait amplitude, 0 standing .. 1 full walk
    sway: np.ndarray  # sideways sway, m
    wrist_targets: np.ndarray | None = None  # (P, 2, 3) world targets for the wrists; NaN: free


@dataclasses.dataclass
class BodyState:
    """Posed bodies at one instant: the joint-angle state, every joint's world position
    (P, len(JOINTS), 3) and global rotation (P, len(JOINTS), 3, 3)."""

    pose: ArticulatedPose
    joints: np.ndarray
    rotations: np.ndarray

    def truth(self, k: int, decimals: int) -> tuple[dict, dict]:
        """Person k's truth: each joint of TRUTH_JOINTS's world position (x, y, z), and its
        angles: the rotation vector (radians) of its rotation relative to its parent (the
        pelvis's relative to the world; identity is the rest pose), rounded."""
        angles = rotation_vectors(self.pose.local[k, : len(TRUTH_JOINTS)])
        return (
            {
                n: tuple(round(float(c), decimals) for c in self.joints[k, J[n]])
                for n in TRUTH_JOINTS
            },
            {n: tuple(round(float(c), decimals) for c in angles[J[n]]) for n in TRUTH_JOINTS},
        )

    def head_tops(self, shapes: list[BodyShape]) -> np.ndarray:
        """(P,) height of the top of each head ellipsoid, m."""
        head = J["head"]
        radii = np.array([s.head for s in shapes]).reshape(-1, 3)
        reach = np.linalg.norm(self.rotations[:, head, 2, :] * radii, axis=1)
        return self.joints[:, head, 2] + reach


def locals_from_globals(rotations: np.ndarray) -> np.ndarray:
    """Each joint's rotation relative to its parent, from global rotations (P, J, 3, 3)."""
    local = rotations.copy()
    parent = BODY_PARENTS[1:]
    local[:, 1:] = np.swapaxes(rotations[:, parent], -1, -2) @ rotations[:, 1:]
    return local


def ground(positions: np.ndarray, shapes: list[BodyShape]) -> np.ndarray:
    """(P,) how far each body must rise for its lower foot (ankle or toe, at its
    standing height) to rest on the floor."""
    lows = []
    for k, shape in enumerate(shapes):
        ankles = positions[k, [J["left_ankle"], J["right_ankle"]], 2] - shape.ankle_height
        toes = positions[k, [J["left_toe"], J["right_toe"]], 2] - shape.toe_height
        lows.append(min(ankles.min(), toes.min()))
    return -np.array(lows)


class BodyModel:
    """Shapes, gait, posing and meshes of humanoid bodies (see the module docstring).

    ``shape_seed`` draws each person's shape from their index (the same person gets
    the same shape in every process); ``varied`` False gives everyone the standard shape.
    """

    def __init__(
        self,
        params=None,  # noqa: ANN001 - Params
        shape_seed: np.random.SeedSequence | None = None,
        varied: bool = False,
    ) -> None:
        self.params = params if params is not None else BODY_PARAMS.create()
        self.shape_seed = shape_seed if shape_seed is not None else np.random.SeedSequence(0)
        self.varied = varied
        self._shapes: dict[tuple[int, float], BodyShape] = {}
        p = self.params
        cylinder = o3d.geometry.TriangleMesh.create_cylinder(
            1.0, 1.0, resolution=int(p.limb_segments), split=1
        )
        self._cyl_v = np.asarray(cylinder.vertices) + [0.0, 0.0, 0.5]  # z in [0, 1]
        self._cyl_t = np.asarray(cylinder.triangles)
        sphere = o3d.geometry.TriangleMesh.create_sphere(1.0, resolution=int(p.head_resolution))
        self._sph_v = np.asarray(sphere.vertices)
        self._sph_t = np.asarray(sphere.triangles)
        # Template of one person: head first, then the cylinders in PARTS order.
        n_cyl_v, n_sph_v = len(self._cyl_v), len(self._sph_v)
        triangles = [self._sph_t]
        centroid = self._sph_v[self._sph_t].mean(axis=1)
        head_material = np.where(
            (centroid[:, 2] > 0.2) | ((centroid[:, 0] < -0.2) & (centroid[:, 2] > -0.4)), HAIR, SKIN
        )
        materials = [head_material]
        part_of_triangle = [np.zeros(len(self._sph_t), dtype=np.int16)]
        for k, part in enumerate(CYLINDERS):
            triangles.append(self._cyl_t + n_sph_v + k * n_cyl_v)
            materials.append(np.full(len(self._cyl_t), part.material))
            part_of_triangle.append(np.full(len(self._cyl_t), k + 1, dtype=np.int16))
        self.vertices_per_person = n_sph_v + len(CYLINDERS) * n_cyl_v
        # Each limb's cap vertices (ring and centre) at its base and its top, paired.
        base = np.flatnonzero(np.isclose(self._cyl_v[:, 2], 0.0))
        top = np.flatnonzero(np.isclose(self._cyl_v[:, 2], 1.0))
        pair = np.argmin(
            np.linalg.norm(self._cyl_v[base][:, None, :2] - self._cyl_v[top][None, :, :2], axis=2),
            axis=1,
        )
        self._cap_base, self._cap_top = base, top[pair]
        self.template_triangles = np.concatenate(triangles).astype(np.uint32)
        self.template_material = np.concatenate(materials).astype(np.int32)
        self.template_part = np.concatenate(part_of_triangle)  # index into PART_NAMES
        rng = np.random.default_rng(0)  # fixed fabric texture, the same for every run
        self.template_texture = rng.uniform(-1.0, 1.0, len(self.template_triangles)).astype(
            np.float32
        )
        self._cyl_a = np.array([J[p.a] for p in CYLINDERS])
        self._cyl_b = np.array([J[p.b] for p in CYLINDERS])
        self._cyl_up = np.array([p.reference == "up" for p in CYLINDERS])

    # ---------------------------------------------------------------- shapes
    def shape(self, index: int, height: float) -> BodyShape:
        """Person ``index``'s shape at standing ``height`` (drawn once, from the index)."""
        key = (int(index), float(height))
        if key not in self._shapes:
            if self.varied:
                seed = np.random.SeedSequence(
                    self.shape_seed.entropy, spawn_key=(*self.shape_seed.spawn_key, int(index))
                )
                p = self.params
                shape = BodyShape.varied(
                    height, np.random.default_rng(seed), p.length_spread, p.radius_spread
                )
            else:
                shape = BodyShape.standard(height)
            self._shapes[key] = shape
        return self._shapes[key]

    # ------------------------------------------------------------------ gait
    def walk(self, pose: BodyPose) -> ArticulatedPose:
        """The walking gait's joint angles (root on the floor plane: :meth:`posed` grounds
        it). Legs swing in the sagittal plane (hip flexion alpha, knee flexion beta, the
        foot kept flat), arms opposite to the leg on their side, the upper body sways."""
        p = self.params
        height = np.asarray(pose.height, dtype=np.float64)
        n = len(height)
        phase = np.asarray(pose.phase, dtype=np.float64)
        amp = np.clip(np.asarray(pose.amplitude, dtype=np.float64), 0.0, MAX_GAIT_AMPLITUDE)
        deg = np.pi / 180.0
        rotations = np.broadcast_to(np.eye(3), (n, len(JOINTS), 3, 3)).copy()
        for side, offset in (("left", 0.0), ("right", np.pi)):
            phi = phase + offset
            alpha = amp * p.hip_swing_deg * deg * np.sin(phi)
            beta = (
                p.knee_stance_deg + amp * p.knee_swing_deg * np.maximum(np.cos(phi), 0.0) ** 2
            ) * deg
            rotations[:, J[f"{side}_hip"]] = axis_rotations(1, -alpha)
            rotations[:, J[f"{side}_knee"]] = axis_rotations(1, beta - alpha)
        torso_half = (SHOULDER_Z - HIP_Z) / 2 * height
        lean = np.arcsin(np.clip(np.asarray(pose.sway, dtype=np.float64) / torso_half, -1, 1))
        for name in ("spine", "neck", "head", "chin"):
            rotations[:, J[name]] = axis_rotations(0, -lean)
        down = np.array([0.0, 0.0, -1.0])
        for side, sign, offset in (("left", 1.0, np.pi), ("right", -1.0, 0.0)):
            phi = phase + offset
            gamma = amp * p.arm_swing_deg * deg * np.sin(phi)
            delta = (p.elbow_deg + amp * p.elbow_swing_deg * np.maximum(np.sin(phi), 0.0)) * deg
            abduct = np.full(n, sign * np.sin(p.arm_abduction_deg * deg))
            upper = np.stack([np.sin(gamma), abduct, -np.cos(gamma)], -1)
            fore = np.stack([np.sin(gamma + delta), abduct, -np.cos(gamma + delta)], -1)
            shoulder = swing(np.broadcast_to(down, upper.shape), upper)
            elbow = swing(upper, fore) @ shoulder
            rotations[:, J[f"{side}_shoulder"]] = shoulder
            for name in ("elbow", "wrist", "hand"):
                rotations[:, J[f"{side}_{name}"]] = elbow
        turn = axis_rotations(2, np.asarray(pose.heading, dtype=np.float64))
        local = locals_from_globals(turn[:, None] @ rotations)
        root = np.stack([np.asarray(pose.x), np.asarray(pose.y), np.zeros(n)], -1).astype(float)
        return ArticulatedPose(root, local)

    def posed(
        self, pose: ArticulatedPose, shapes: list[BodyShape], grounded: np.ndarray | None = None
    ) -> BodyState:
        """Forward kinematics of ``pose`` with each person's shape; the people ``grounded``
        marks (default all) are raised or lowered until their lower foot meets the floor."""
        offsets = np.array([s.offsets for s in shapes]).reshape(-1, len(JOINTS), 3)
        positions, rotations = forward_kinematics(offsets, pose)
        lift = ground(positions, shapes)
        if grounded is not None:
            lift = np.where(grounded, lift, 0.0)
        positions[..., 2] += lift[:, None]
        root = pose.root.copy()
        root[:, 2] += lift
        return BodyState(ArticulatedPose(root, pose.local), positions, rotations)

    def joints(self, pose: BodyPose, shapes: list[BodyShape] | None = None) -> BodyState:
        """Walking bodies posed: gait, feet on the floor, wrists on their targets."""
        if shapes is None:
            shapes = [BodyShape.standard(h) for h in np.asarray(pose.height, dtype=float)]
        state = self.posed(self.walk(pose), shapes)
        if pose.wrist_targets is not None:
            state = self.reach(state, np.asarray(pose.wrist_targets, dtype=np.float64), shapes)
        return state

    def reach(self, state: BodyState, targets: np.ndarray, shapes: list[BodyShape]) -> BodyState:
        """Bend arms so the wrists reach their targets (two-link inverse kinematics,
        law of cosines), the elbow hanging down and out; the angles follow."""
        world, rotations = state.joints, state.rotations.copy()
        for person in np.flatnonzero(
            np.all(np.isfinite(targets.reshape(len(targets), -1)), axis=1)
        ):
            offsets = shapes[person].offsets
            for k, side in enumerate(("left", "right")):
                s, e, w = (J[f"{side}_{n}"] for n in ("shoulder", "elbow", "wrist"))
                a, b = np.linalg.norm(offsets[e]), np.linalg.norm(offsets[w])
                shoulder = world[person, s]
                reach = targets[person, k] - shoulder
                dist = float(np.linalg.norm(reach))
                dist = min(max(dist, abs(a - b) + 1e-3), a + b - 1e-3)
                axis = reach / max(np.linalg.norm(reach), 1e-9)
                cos_a = (a * a + dist * dist - b * b) / (2 * a * dist)
                # The elbow bends in the plane of the reach, down, out and back.
                side_dir = shoulder - world[person, J["neck"]]
                side_dir = side_dir / max(np.linalg.norm(side_dir), 1e-9)
                back = np.cross(side_dir, [0.0, 0.0, 1.0]) * (1.0 if side == "left" else -1.0)
                hint = np.array([0.0, 0.0, -1.0]) + 0.5 * side_dir + 0.5 * back
                ortho = hint - (hint @ axis) * axis
                ortho /= max(np.linalg.norm(ortho), 1e-9)
                elbow = shoulder + a * (cos_a * axis + np.sqrt(max(1 - cos_a**2, 0.0)) * ortho)
                wrist = shoulder + axis * dist
                upper_now, fore_now = (
                    world[person, e] - shoulder,
                    world[person, w] - world[person, e],
                )
                upper_turn = swing(upper_now, elbow - shoulder)
                fore_turn = swing(upper_turn @ fore_now, wrist - elbow) @ upper_turn
                rotations[person, s] = upper_turn @ rotations[person, s]
                for name in ("elbow", "wrist", "hand"):
                    joint = J[f"{side}_{name}"]
                    rotations[person, joint] = fore_turn @ rotations[person, joint]
        local = locals_from_globals(rotations)
        pose = ArticulatedPose(state.pose.root, local)
        return self.posed(pose, shapes, grounded=np.zeros(len(shapes), dtype=bool))

    # ------------------------------------------------------------------ mesh
    def hulls(self, vertices: np.ndarray) -> list[np.ndarray]:
        """Point groups whose convex hulls together cover every body: each head, and each
        half of each limb (its cap rings and the ring halfway). Arrays (G, K, 3), one per
        group size; a renderer casts only the rays that can meet these hulls."""
        n = len(vertices)
        heads = vertices[:, : len(self._sph_v)]
        limbs = vertices[:, len(self._sph_v) :].reshape(n, len(CYLINDERS), len(self._cyl_v), 3)
        base, top = limbs[:, :, self._cap_base], limbs[:, :, self._cap_top]
        middle = (base + top) / 2
        halves = np.concatenate(
            [np.concatenate([base, middle], axis=2), np.concatenate([middle, top], axis=2)], axis=1
        )
        return [heads, halves.reshape(-1, halves.shape[2], 3)]

    def vertices(self, state: BodyState, shapes: list[BodyShape]) -> np.ndarray:
        """Mesh vertices of every body, (P, vertices_per_person, 3), world frame."""
        joints, rotations = state.joints, state.rotations
        n = len(joints)
        # Head: an ellipsoid turned with the head joint.
        radii = np.array([s.head for s in shapes]).reshape(n, 3)
        head_axes = rotations[:, J["head"]] * radii[:, None, :]  # columns: scaled axes
        head = np.einsum("pij,vj->pvi", head_axes, self._sph_v) + joints[:, J["head"]][:, None, :]
        # Limbs: z from joint a to joint b, x along the base joint's reference axis.
        a = joints[:, self._cyl_a]  # (P, C, 3)
        axis = joints[:, self._cyl_b] - a
        length = np.linalg.norm(axis, axis=2, keepdims=True)
        unit = axis / np.maximum(length, 1e-9)
        frames = rotations[:, self._cyl_a]  # (P, C, 3, 3)
        reference = np.where(self._cyl_up[None, :, None], frames[..., 2], frames[..., 0])
        x = reference - np.sum(reference * unit, axis=2, keepdims=True) * unit
        x_norm = np.linalg.norm(x, axis=2, keepdims=True)
        x = np.where(x_norm > 1e-6, x / np.maximum(x_norm, 1e-9), frames[..., 1])
        y = np.cross(unit, x)
        part_radii = np.array([s.radii for s in shapes]).reshape(n, len(CYLINDERS), 4)
        z = self._cyl_v[:, 2]
        rx = part_radii[..., :1] + (part_radii[..., 2:3] - part_radii[..., :1]) * z  # (P, C, V)
        ry = part_radii[..., 1:2] + (part_radii[..., 3:4] - part_radii[..., 1:2]) * z
        limbs = (
            a[:, :, None, :]
            + x[:, :, None, :] * (rx * self._cyl_v[:, 0])[..., None]
            + y[:, :, None, :] * (ry * self._cyl_v[:, 1])[..., None]
            + axis[:, :, None, :] * z[None, None, :, None]
        )
        return np.concatenate([head, limbs.reshape(n, limbs.shape[1] * limbs.shape[2], 3)], axis=1)
