"""Humanoid bodies: joints from a walking gait, and a triangle mesh around them.

A body is 15 parts (head, neck, torso, upper arms, forearms, hands, thighs,
shins, feet) in the spirit of MDCA's extended-cylinder shape model: each
limb is an elliptic cylinder between two joints, the head an ellipsoid.
Segment lengths and radii are fractions of the standing height ``H`` from
the anthropometric table of Drillis and Contini as given in D. A. Winter,
*Biomechanics and Motor Control of Human Movement* (4th ed., Wiley 2009),
figure 4.1: ankle 0.039 H, knee 0.285 H, hip 0.530 H, shoulder 0.818 H,
chin 0.870 H, upper arm 0.186 H, forearm 0.146 H, hand 0.108 H, foot
0.152 H, shoulder width 0.259 H, hip width 0.191 H.

Everything is vectorised over people: ``P`` people give ``(P, J, 3)``
joints and one concatenated mesh. The body frame is x forward, y left, z up,
origin on the floor under the pelvis.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import open3d as o3d

from optrack.params import Param, Schema, register

__all__ = [
    "BODY_PARAMS",
    "JOINTS",
    "TRUTH_JOINTS",
    "BodyModel",
    "BodyPose",
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
        ],
        help="The simulated people's body shape and walking gait.",
    )
)

# Joint indices (body frame, then world). The first 16 are ground truth.
JOINTS = (
    "head",
    "neck",
    "spine",
    "pelvis",
    "shoulder_l",
    "elbow_l",
    "wrist_l",
    "shoulder_r",
    "elbow_r",
    "wrist_r",
    "hip_l",
    "knee_l",
    "ankle_l",
    "hip_r",
    "knee_r",
    "ankle_r",
    "hand_l",
    "hand_r",
    "toe_l",
    "toe_r",
    "chin",
)
TRUTH_JOINTS = JOINTS[:16]
J = {name: i for i, name in enumerate(JOINTS)}

# Anthropometric fractions of height (Winter 2009, fig. 4.1).
ANKLE_Z, KNEE_Z, HIP_Z, SHOULDER_Z, CHIN_Z = 0.039, 0.285, 0.530, 0.818, 0.870
UPPER_ARM, FOREARM, HAND, FOOT = 0.186, 0.146, 0.108, 0.152
SHOULDER_HALF_WIDTH = 0.259 / 2 * 0.8  # joint centres sit inside the outer width
HIP_HALF_WIDTH = 0.191 / 2 * 0.55
HEAD_CENTER_Z, HEAD_RADII = 0.935, (0.057, 0.045, 0.065)  # forward, side, up
TOE_FORWARD = 0.11  # ankle to toe, along the foot
THIGH = HIP_Z - KNEE_Z
SHIN = KNEE_Z - ANKLE_Z

MAX_GAIT_AMPLITUDE = 1.2  # a brisk walk swings a little more than a normal one
TOE_LIFT = 0.02  # the toe sits this fraction of H below the ankle...
TOE_CLEARANCE = 0.005  # ...but never below this height above the floor, m
HAND_REACH = 0.8  # the hand segment ends at this share of the hand length

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
    reference: str = "forward"  # "forward" or "up": what the first radius is aligned with


PARTS = (
    Part("head", "head", None, HEAD_RADII[:2], SKIN),
    Part("neck", "neck", "chin", (0.028, 0.03), SKIN),
    Part("torso", "pelvis", "neck", (0.06, 0.095), SHIRT),
    Part("upper_arm_l", "shoulder_l", "elbow_l", (0.025, 0.025), SHIRT),
    Part("forearm_l", "elbow_l", "wrist_l", (0.021, 0.021), SHIRT),
    Part("hand_l", "wrist_l", "hand_l", (0.012, 0.024), SKIN),
    Part("upper_arm_r", "shoulder_r", "elbow_r", (0.025, 0.025), SHIRT),
    Part("forearm_r", "elbow_r", "wrist_r", (0.021, 0.021), SHIRT),
    Part("hand_r", "wrist_r", "hand_r", (0.012, 0.024), SKIN),
    Part("thigh_l", "hip_l", "knee_l", (0.045, 0.045), TROUSERS),
    Part("shin_l", "knee_l", "ankle_l", (0.03, 0.03), TROUSERS),
    Part("foot_l", "ankle_l", "toe_l", (0.02, 0.025), SHOES, "up"),
    Part("thigh_r", "hip_r", "knee_r", (0.045, 0.045), TROUSERS),
    Part("shin_r", "knee_r", "ankle_r", (0.03, 0.03), TROUSERS),
    Part("foot_r", "ankle_r", "toe_r", (0.02, 0.025), SHOES, "up"),
)
CYLINDERS = tuple(p for p in PARTS if p.b is not None)


@dataclasses.dataclass
class BodyPose:
    """What a body's shape needs at one instant, for P people (arrays of length P)."""

    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray  # radians, the direction the body faces
    height: np.ndarray  # standing height, m
    phase: np.ndarray  # gait phase, radians
    amplitude: np.ndarray  # gait amplitude, 0 standing .. 1 full walk
    sway: np.ndarray  # sideways sway, m
    wrist_targets: np.ndarray | None = None  # (P, 2, 3) world targets for the wrists; NaN: free


def _rot_z(angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    zeros, ones = np.zeros_like(c), np.ones_like(c)
    return np.stack(
        [
            np.stack([c, -s, zeros], -1),
            np.stack([s, c, zeros], -1),
            np.stack([zeros, zeros, ones], -1),
        ],
        axis=-2,
    )


class BodyModel:
    """Joints and meshes of humanoid bodies (see the module docstring)."""

    def __init__(self, params=None) -> None:  # noqa: ANN001 - Params
        self.params = params if params is not None else BODY_PARAMS.create()
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
        self.template_part = np.concatenate(part_of_triangle)
        rng = np.random.default_rng(0)  # fixed fabric texture, the same for every run
        self.template_texture = rng.uniform(-1.0, 1.0, len(self.template_triangles)).astype(
            np.float32
        )
        self._cyl_a = np.array([J[p.a] for p in CYLINDERS])
        self._cyl_b = np.array([J[p.b] for p in CYLINDERS])
        self._cyl_r = np.array([p.radii for p in CYLINDERS])
        self._cyl_up = np.array([p.reference == "up" for p in CYLINDERS])

    # ---------------------------------------------------------------- joints
    def joints(self, pose: BodyPose) -> np.ndarray:
        """World joint positions, (P, len(JOINTS), 3)."""
        p = self.params
        H = np.asarray(pose.height, dtype=np.float64)[:, None]
        n = len(H)
        phase = np.asarray(pose.phase, dtype=np.float64)
        amp = np.clip(np.asarray(pose.amplitude, dtype=np.float64), 0.0, MAX_GAIT_AMPLITUDE)
        deg = np.pi / 180.0
        out = np.zeros((n, len(JOINTS), 3))

        # Legs in the sagittal plane: hip flexion alpha (forward +), knee flexion beta.
        ankle_rel = []
        for side, sign, offset in (("l", 1.0, 0.0), ("r", -1.0, np.pi)):
            phi = phase + offset
            alpha = amp * p.hip_swing_deg * deg * np.sin(phi)
            beta = (
                p.knee_stance_deg + amp * p.knee_swing_deg * np.maximum(np.cos(phi), 0.0) ** 2
            ) * deg
            thigh = np.stack([np.sin(alpha), np.zeros(n), -np.cos(alpha)], -1) * THIGH * H
            shin = (
                np.stack([np.sin(alpha - beta), np.zeros(n), -np.cos(alpha - beta)], -1) * SHIN * H
            )
            hip = np.zeros((n, 3))
            hip[:, 1] = sign * HIP_HALF_WIDTH * H[:, 0]
            out[:, J[f"hip_{side}"]] = hip
            out[:, J[f"knee_{side}"]] = hip + thigh
            out[:, J[f"ankle_{side}"]] = hip + thigh + shin
            ankle_rel.append(out[:, J[f"ankle_{side}"], 2])
        # The lower ankle rests at ankle height: this gives the gait's natural bob.
        hip_z = ANKLE_Z * H[:, 0] - np.minimum(*ankle_rel)
        for side in "lr":
            for name in ("hip", "knee", "ankle"):
                out[:, J[f"{name}_{side}"], 2] += hip_z
            toe = out[:, J[f"ankle_{side}"]].copy()
            toe[:, 0] += TOE_FORWARD * H[:, 0]
            toe[:, 2] = np.maximum(toe[:, 2] - TOE_LIFT * H[:, 0], TOE_CLEARANCE)
            out[:, J[f"toe_{side}"]] = toe
        bob = hip_z - HIP_Z * H[:, 0]

        sway = np.asarray(pose.sway, dtype=np.float64)
        out[:, J["pelvis"]] = np.stack([np.zeros(n), sway, hip_z], -1)
        out[:, J["spine"]] = np.stack(
            [np.zeros(n), sway, ((HIP_Z + SHOULDER_Z) / 2) * H[:, 0] + bob], -1
        )
        out[:, J["neck"]] = np.stack([np.zeros(n), sway, SHOULDER_Z * H[:, 0] + bob], -1)
        out[:, J["chin"]] = np.stack([np.zeros(n), sway, CHIN_Z * H[:, 0] + bob], -1)
        out[:, J["head"]] = np.stack([np.zeros(n), sway, HEAD_CENTER_Z * H[:, 0] + bob], -1)

        # Arms swing opposite to the leg on the same side.
        for side, sign, offset in (("l", 1.0, np.pi), ("r", -1.0, 0.0)):
            phi = phase + offset
            gamma = amp * p.arm_swing_deg * deg * np.sin(phi)
            delta = (p.elbow_deg + amp * p.elbow_swing_deg * np.maximum(np.sin(phi), 0.0)) * deg
            abduct = p.arm_abduction_deg * deg
            shoulder = out[:, J["neck"]].copy()
            shoulder[:, 1] += sign * SHOULDER_HALF_WIDTH * H[:, 0]
            upper = np.stack([np.sin(gamma), sign * np.full(n, np.sin(abduct)), -np.cos(gamma)], -1)
            fore = np.stack(
                [np.sin(gamma + delta), sign * np.full(n, np.sin(abduct)), -np.cos(gamma + delta)],
                -1,
            )
            upper /= np.linalg.norm(upper, axis=1, keepdims=True)
            fore /= np.linalg.norm(fore, axis=1, keepdims=True)
            elbow = shoulder + upper * UPPER_ARM * H
            wrist = elbow + fore * FOREARM * H
            out[:, J[f"shoulder_{side}"]] = shoulder
            out[:, J[f"elbow_{side}"]] = elbow
            out[:, J[f"wrist_{side}"]] = wrist
            out[:, J[f"hand_{side}"]] = wrist + fore * HAND * H * HAND_REACH

        # Body frame -> world.
        rotation = _rot_z(np.asarray(pose.heading, dtype=np.float64))
        world = np.einsum("pij,pkj->pki", rotation, out)
        world[..., 0] += np.asarray(pose.x)[:, None]
        world[..., 1] += np.asarray(pose.y)[:, None]
        if pose.wrist_targets is not None:
            self._reach(world, pose, H[:, 0])
        return world

    @staticmethod
    def _reach(world: np.ndarray, pose: BodyPose, height: np.ndarray) -> None:
        """Bend arms so the wrists reach their targets (two-link inverse kinematics,
        law of cosines), the elbow hanging down and out."""
        targets = np.asarray(pose.wrist_targets, dtype=np.float64)
        for person in np.flatnonzero(
            np.all(np.isfinite(targets.reshape(len(targets), -1)), axis=1)
        ):
            H = height[person]
            a, b = UPPER_ARM * H, FOREARM * H
            for k, side in enumerate("lr"):
                shoulder = world[person, J[f"shoulder_{side}"]]
                target = targets[person, k]
                reach = target - shoulder
                dist = float(np.linalg.norm(reach))
                dist = min(max(dist, abs(a - b) + 1e-3), a + b - 1e-3)
                axis = reach / max(np.linalg.norm(reach), 1e-9)
                cos_a = (a * a + dist * dist - b * b) / (2 * a * dist)
                # The elbow bends in the plane of the reach, down, out and back.
                side_dir = world[person, J[f"shoulder_{side}"]] - world[person, J["neck"]]
                side_dir /= max(np.linalg.norm(side_dir), 1e-9)
                back = np.cross(side_dir, [0.0, 0.0, 1.0]) * (1.0 if side == "l" else -1.0)
                hint = np.array([0.0, 0.0, -1.0]) + 0.5 * side_dir + 0.5 * back
                ortho = hint - (hint @ axis) * axis
                ortho /= max(np.linalg.norm(ortho), 1e-9)
                elbow = shoulder + a * (cos_a * axis + np.sqrt(max(1 - cos_a**2, 0.0)) * ortho)
                wrist = shoulder + axis * dist
                fore = (wrist - elbow) / max(np.linalg.norm(wrist - elbow), 1e-9)
                world[person, J[f"elbow_{side}"]] = elbow
                world[person, J[f"wrist_{side}"]] = wrist
                world[person, J[f"hand_{side}"]] = wrist + fore * HAND * H * HAND_REACH

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

    def vertices(self, joints: np.ndarray, pose: BodyPose) -> np.ndarray:
        """Mesh vertices of every body, (P, vertices_per_person, 3), world frame."""
        H = np.asarray(pose.height, dtype=np.float64)
        n = len(H)
        forward = np.stack([np.cos(pose.heading), np.sin(pose.heading), np.zeros(n)], -1)
        # Head: an ellipsoid aligned with the heading.
        left = np.stack([-forward[:, 1], forward[:, 0], np.zeros(n)], -1)
        up = np.broadcast_to([0.0, 0.0, 1.0], (n, 3))
        head_axes = np.stack(
            [
                forward * HEAD_RADII[0] * H[:, None],
                left * HEAD_RADII[1] * H[:, None],
                up * HEAD_RADII[2] * H[:, None],
            ],
            axis=2,
        )  # (P, 3, 3): columns are the scaled axes
        head = np.einsum("pij,vj->pvi", head_axes, self._sph_v) + joints[:, J["head"]][:, None, :]
        # Cylinders: z from joint a to joint b, x along the reference direction.
        a = joints[:, self._cyl_a]  # (P, C, 3)
        b = joints[:, self._cyl_b]
        axis = b - a
        length = np.linalg.norm(axis, axis=2, keepdims=True)
        unit = axis / np.maximum(length, 1e-9)
        reference = np.where(self._cyl_up[None, :, None], up[:, None, :], forward[:, None, :])
        x = reference - np.sum(reference * unit, axis=2, keepdims=True) * unit
        x_norm = np.linalg.norm(x, axis=2, keepdims=True)
        fallback = np.broadcast_to(left[:, None, :], x.shape)
        x = np.where(x_norm > 1e-6, x / np.maximum(x_norm, 1e-9), fallback)
        y = np.cross(unit, x)
        radii = self._cyl_r[None] * H[:, None, None]  # (P, C, 2)
        frame = np.stack([x * radii[..., :1], y * radii[..., 1:], axis], axis=3)  # (P, C, 3, 3)
        limbs = np.einsum("pcij,vj->pcvi", frame, self._cyl_v) + a[:, :, None, :]
        return np.concatenate([head, limbs.reshape(n, -1, 3)], axis=1)
