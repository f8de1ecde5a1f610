"""Procedural motions on the same joint-angle state as motion capture: walk, wave,
crouch and turn on the spot.

Each is a :class:`~optrack.sim.mocap.Motion` sampled at :data:`RATE` on a standard
body of :data:`REFERENCE_HEIGHT`, so that a person performs it exactly as they would a
BVH clip (retargeted onto their shape, placed, looped). All four end in the pose they
start in (``cyclic``) and keep the feet on the floor at every instant (``grounded``).

- ``walk``: one stride of the walking gait (:meth:`BodyModel.walk`) at full amplitude
  and ``full_gait_speed``; looped, the person walks on.
- ``turn``: stepping on the spot at a third of the gait's amplitude while turning a
  quarter turn to the left per loop (2 s).
- ``wave``: standing, the right arm rises (0.8 s), the forearm waves from side to
  side at 1.6 Hz, the arm comes down (4 s in all).
- ``crouch``: the hips and knees bend (80 and 115 degrees), the back leans forward
  (30 degrees), the arms reach forward, and back up (3.6 s); the pelvis moves back so
  that the feet stay where they are.
"""

from __future__ import annotations

import numpy as np

from optrack.sim.articulated import (
    BODY_PARENTS,
    ArticulatedPose,
    axis_rotations,
    forward_kinematics,
    quaternions,
    swing,
)
from optrack.sim.body import BodyModel, BodyPose, BodyShape, J, locals_from_globals
from optrack.sim.mocap import Motion

__all__ = ["PROCEDURAL", "RATE", "REFERENCE_HEIGHT", "procedural_motion"]

PROCEDURAL = ("walk", "wave", "crouch", "turn")
RATE = 60.0  # frames per second of a procedural motion
REFERENCE_HEIGHT = 1.72  # m: the standard body they are made on

TURN_SECONDS, TURN_PER_LOOP, TURN_AMPLITUDE = 2.0, np.pi / 2, 0.35
WAVE_SECONDS, WAVE_RAISE, WAVE_HZ, WAVE_SWING = 4.0, 0.8, 1.6, 0.45
WAVE_UPPER = np.array([0.15, -0.55, 0.82])  # the raised right upper arm: up and out
CROUCH_SECONDS = 3.6
CROUCH_KEYS = (0.3, 1.5, 2.1, 3.3)  # start down, bottom, start up, standing again
CROUCH_HIP, CROUCH_KNEE, CROUCH_LEAN, CROUCH_ARMS = np.radians((80.0, 115.0, 30.0, 60.0))


def _ease(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _globals(local: np.ndarray) -> np.ndarray:
    """Global rotations (F, J, 3, 3) from local ones."""
    out = local.copy()
    for j in range(1, local.shape[1]):
        out[:, j] = out[:, BODY_PARENTS[j]] @ local[:, j]
    return out


def _times(seconds: float) -> np.ndarray:
    return np.linspace(0.0, seconds, int(round(seconds * RATE)) + 1)


def _standing(t: np.ndarray, **gait: np.ndarray | float) -> BodyPose:
    n = len(t)
    values = {
        "x": 0.0,
        "y": 0.0,
        "heading": 0.0,
        "phase": 0.0,
        "amplitude": 0.0,
        "sway": 0.0,
    } | gait
    return BodyPose(
        height=np.full(n, REFERENCE_HEIGHT),
        **{k: np.broadcast_to(np.asarray(v, dtype=float), (n,)).copy() for k, v in values.items()},
    )


def _arm(rotations: np.ndarray, side: str, upper: np.ndarray, fore: np.ndarray) -> None:
    """Point the arm on ``side`` along ``upper`` then ``fore`` (global directions)."""
    down = np.broadcast_to([0.0, 0.0, -1.0], upper.shape)
    shoulder = swing(down, upper)
    elbow = swing(upper, fore) @ shoulder
    rotations[:, J[f"{side}_shoulder"]] = shoulder
    for name in ("elbow", "wrist", "hand"):
        rotations[:, J[f"{side}_{name}"]] = elbow


def _walk(body: BodyModel) -> tuple[np.ndarray, ArticulatedPose]:
    speed = float(body.params.full_gait_speed)
    period = float(body.params.stride_per_height) * REFERENCE_HEIGHT / speed
    t = _times(period)
    pose = body.walk(_standing(t, x=speed * t, phase=2 * np.pi * t / period, amplitude=1.0))
    return t, pose


def _turn(body: BodyModel) -> tuple[np.ndarray, ArticulatedPose]:
    t = _times(TURN_SECONDS)
    gait = {
        "heading": TURN_PER_LOOP * t / TURN_SECONDS,
        "phase": 4 * np.pi * t / TURN_SECONDS,
        "amplitude": TURN_AMPLITUDE,
    }
    return t, body.walk(_standing(t, **gait))


def _wave(body: BodyModel) -> tuple[np.ndarray, ArticulatedPose]:
    t = _times(WAVE_SECONDS)
    pose = body.walk(_standing(t))
    rotations = _globals(pose.local)
    raised = (_ease(t / WAVE_RAISE) * _ease((WAVE_SECONDS - t) / WAVE_RAISE))[:, None]
    hang_upper = rotations[:, J["right_shoulder"]] @ np.array([0.0, 0.0, -1.0])
    hang_fore = rotations[:, J["right_elbow"]] @ np.array([0.0, 0.0, -1.0])
    swing_angle = WAVE_SWING * np.sin(2 * np.pi * WAVE_HZ * (t - WAVE_RAISE))
    wave_fore = np.stack([np.full_like(t, 0.1), -np.sin(swing_angle), np.cos(swing_angle)], -1)
    upper = (1 - raised) * hang_upper + raised * WAVE_UPPER / np.linalg.norm(WAVE_UPPER)
    fore = (1 - raised) * hang_fore + raised * wave_fore
    _arm(rotations, "right", upper, fore)
    return t, ArticulatedPose(pose.root, locals_from_globals(rotations))


def _crouch(body: BodyModel) -> tuple[np.ndarray, ArticulatedPose]:
    t = _times(CROUCH_SECONDS)
    a, b, c, d = CROUCH_KEYS
    depth = _ease((t - a) / (b - a)) * _ease((d - t) / (d - c))
    pose = body.walk(_standing(t))
    rotations = _globals(pose.local)
    hip, knee = CROUCH_HIP * depth, CROUCH_KNEE * depth
    lean = axis_rotations(1, CROUCH_LEAN * depth)
    for side in ("left", "right"):
        rotations[:, J[f"{side}_hip"]] = axis_rotations(1, -hip)
        rotations[:, J[f"{side}_knee"]] = axis_rotations(1, knee - hip)
    for name in ("spine", "neck", "head", "chin"):
        rotations[:, J[name]] = lean @ rotations[:, J[name]]
    reach = CROUCH_ARMS * depth
    for side, sign in (("left", 1.0), ("right", -1.0)):
        upper = np.stack([np.sin(reach), np.full_like(t, 0.1 * sign), -np.cos(reach)], -1)
        _arm(rotations, side, upper, upper)
    pose = ArticulatedPose(pose.root, locals_from_globals(rotations))
    # Keep the feet where they are: the pelvis moves back as the knees come forward.
    shape = BodyShape.standard(REFERENCE_HEIGHT)
    positions, _ = forward_kinematics(
        np.broadcast_to(shape.offsets, (len(t), *shape.offsets.shape)), pose
    )
    ankles = positions[:, [J["left_ankle"], J["right_ankle"]], 0].mean(axis=1)
    pose.root[:, 0] -= ankles - ankles[0]
    return t, pose


_MAKERS = {"walk": _walk, "turn": _turn, "wave": _wave, "crouch": _crouch}


def procedural_motion(name: str, params=None) -> Motion:  # noqa: ANN001 - Params
    """The procedural motion ``name`` (one of :data:`PROCEDURAL`)."""
    body = BodyModel(params)
    t, pose = _MAKERS[name](body)
    return Motion(
        name=name,
        frame_time=float(t[1] - t[0]),
        local=quaternions(pose.local),
        hips=pose.root.copy(),
        leg_length=BodyShape.standard(REFERENCE_HEIGHT).leg_length,
        grounded=True,
        cyclic=True,
    )
