"""Initialisation (MDCA §IV-D): coarse to fine, from the torso to the arms, then the legs.

A person may enter in any standing pose. The torso is found first: its
position from the cloud's middle, its heading's axis from the cloud's widest
horizontal direction at chest height (the shoulders' line), searched again from
45 degrees either side of it (swinging arms widen the band the wrong way), then
tried both ways (facing either side of that axis); it is annealed over
``init_layers`` layers from a broad spread. Then each arm, from angles drawn
uniformly within its joint limits, is annealed the same way against the fixed
torso; then each
leg. A second, finer round repeats the partitions from that estimate; of the
two headings, the one whose full-body likelihood is higher is kept (the feet
and the knees, which bend one way only, tell front from back). Last, each arm is
tried hanging at rest and kept so unless the pose found explains the cloud
clearly better (``hang_arm``: an arm the sensors do not see hangs).

While tracking starts, the tracker tries the legs the other way round
(``swap_legs``) and the whole body turned round (``turn_around``), each kept
only where the data's likelihood rises by a margin.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from optrack.skeleton.filter import SkeletonFilter, motion_spread
from optrack.skeleton.joints import JOINTS
from optrack.skeleton.likelihood import log_likelihood
from optrack.skeleton.model import (
    DOFS,
    LIMITS,
    PARTITIONS,
    PARTS,
    POINTS,
    BodyShape,
    D,
    forward_kinematics,
    part_geometry,
    rest_state,
)
from optrack.skeleton.prior import arm_collision_cost

__all__ = [
    "LIMBS",
    "body_axis",
    "facing_candidates",
    "height_from_cloud",
    "initialise",
    "initialise_both_ways",
    "initialise_facing",
    "pose_log_likelihood",
    "search_limb",
    "search_limb_again",
    "hang_arm",
    "rest_arm_again",
    "swap_legs",
    "turn_around",
]

LIMBS = ("left_arm", "right_arm", "left_leg", "right_leg")

# Spread of the torso's first particles around the guess: metres for the position,
# radians for the heading and the lean; the spine and neck start straight (a standing
# person is upright; bent, the chest would reach for the arms' points) and are freed by
# the finer rounds.
_TORSO_SPREAD = np.array([0.06, 0.06, 0.06, 0.35, 0.12, 0.12, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
# The heading search's first diffusion for the limbs, radians.
_LIMB_SPREAD = 0.5
# The parts the first torso search is scored on: a standing person's legs are near their
# rest pose, the arms may be anywhere.
_TORSO_AND_LEGS = np.array(
    [k for k, part in enumerate(PARTS) if part.partition in ("torso", "left_leg", "right_leg")]
)
_FINE_ROUNDS = 2
# The finer rounds diffuse as the motion model does over this time (s).
_FINE_DT = 0.05
# Heights (shares of the height) of the feet, and of the shins above them; how far ahead
# of the shins (m) the feet must reach for facing_candidates to be sure of the heading.
_FEET_BAND = (0.05, 0.2)
_FEET_AHEAD = 0.02
# The turns (radians) of the chest band's heading that the body's axis is searched from.
_AXIS_TURNS = (0.0, -0.25 * np.pi, 0.25 * np.pi)
# search_limb's share of particles drawn near the limb's rest pose, their spread (rad),
# and that pose: a limb hanging with its elbow or knee a little bent.
_REST_SHARE = 0.25
_REST_SPREAD = 0.3
_REST = {
    "left_arm": np.array([0.0, 0.1, 0.0, 0.3]),
    "right_arm": np.array([0.0, 0.1, 0.0, 0.3]),
    "left_leg": np.array([0.0, 0.05, 0.0, 0.1]),
    "right_leg": np.array([0.0, 0.05, 0.0, 0.1]),
}
# Coarse searches of each limb at initialisation (one alone sometimes settles on a wrong
# fold of the arm, and the heading it completes then loses to the wrong one).
_LIMB_TRIES = 2
# swap_legs: how far (m) the left knee may be to the left of the right one, along the hips'
# line, for the legs to be tried the other way round. Legs found crossed on the run clip
# with two sensors: -0.25 to +0.05 m; found right: -0.03 to +0.41 m, crossed at the knees
# only as they pass each other.
_KNEES_APART = 0.05
# turn_around: each joint of the body turned round is put where its mirror image (left for
# right) is; the numbers negated in the turned body's first guess (leaning forward, seen
# from behind, is leaning back; a limb swung forward is then swung back).
_MIRROR = [JOINTS.index(j.replace("left", "@").replace("right", "left").replace("@", "right")) for j in JOINTS]  # fmt: skip
_TURN_NEGATED = [
    DOFS.index(name)
    for name in ("root_pitch", "root_roll", "spine_flex", "spine_lateral", "neck_flex",
                 "neck_lateral", "left_shoulder_flex", "right_shoulder_flex", "left_hip_flex",
                 "right_hip_flex")
]  # fmt: skip
# The least squares' evaluations of the kinematics: a knee cannot bend forward, so the
# mirror image is never met exactly and the solver would creep on (to 1,800 evaluations,
# 1.9 s); the refinement after it finishes the pose.
_TURN_EVALUATIONS = 80
# _reach's finite-difference step (radians, relative above 1 rad).
_DIFF_STEP = 1e-3
# Rounds of every partition refining both poses (as found, turned) before they are
# compared, and the particles they anneal (a pose near the start: fewer than a frame's).
_TURN_ROUNDS = 2
_TURN_PARTICLES = 1000
# hang_arm's particles (one arm's four angles from near its rest pose).
_HANG_PARTICLES = 500
# Points higher than this share of the height are the chest and shoulders.
_CHEST_BAND = (0.62, 0.8)


def height_from_cloud(points: np.ndarray) -> float:
    """A standing person's height from their cloud (world frame, floor at z = 0): the
    top of the head, taken as a high percentile so that a stray point does not count."""
    return float(np.percentile(np.asarray(points)[:, 2], 99.5))


def facing_candidates(
    points: np.ndarray, shape: BodyShape, heading: float | None = None
) -> tuple[tuple[float, ...], bool]:
    """The headings (radians) to try, most likely first, and whether the first is sure.

    Both lie along ``heading``'s axis, by default square to the widest horizontal
    direction of the chest band of the cloud (a standing person's shoulders are wider
    than their chest is deep). The feet tell which way: the points at the floor reach
    further forward than the shins above them; sure when they do by more than
    ``_FEET_AHEAD`` metres (:func:`initialise` completes both all the same: mid-stride
    the feet can point the wrong way)."""
    z = points[:, 2]
    if heading is None:
        band = points[(z > _CHEST_BAND[0] * shape.height) & (z < _CHEST_BAND[1] * shape.height)]
        if len(band) < 3:
            band = points
        xy = band[:, :2] - band[:, :2].mean(axis=0)
        _, vectors = np.linalg.eigh(xy.T @ xy)
        across = vectors[:, 1]  # the widest direction: the shoulders' line
        heading = float(np.arctan2(across[1], across[0]) - np.pi / 2)
    feet = points[z < _FEET_BAND[0] * shape.height]
    shins = points[(z > _FEET_BAND[0] * shape.height) & (z < _FEET_BAND[1] * shape.height)]
    if len(feet) < 3 or len(shins) < 3:
        return (heading, heading + np.pi), False
    ahead = float(
        (feet[:, :2].mean(axis=0) - shins[:, :2].mean(axis=0)) @ [np.cos(heading), np.sin(heading)]
    )
    if ahead < 0:
        heading += np.pi
    return (heading, heading + np.pi), abs(ahead) > _FEET_AHEAD


def body_axis(filt: SkeletonFilter, points: np.ndarray) -> float:
    """The heading's axis (radians, front or back): the torso searched from the chest
    band's guess and from that turned by 45 degrees each way, the best kept (a runner's
    swinging arms widen the band along the way they run: 44 degrees off on the run clip)."""
    (guess, _), _ = facing_candidates(points, filt.shape)
    best, best_score = guess, -np.inf
    for turn in _AXIS_TURNS:
        torso = _torso_facing(filt, points, guess + turn)
        score = pose_log_likelihood(filt, points, torso)
        if score > best_score:
            best, best_score = float(torso[3]), score
    return best


def pose_log_likelihood(
    filt: SkeletonFilter, points: np.ndarray, state: np.ndarray, prior: bool = True
) -> float:
    """The full-body likelihood (eq. 9, every part) of one pose, less the arms' collision
    prior unless ``prior`` is False."""
    p = filt.params
    pts, rot = forward_kinematics(np.asarray(state)[None], filt.shape)
    geometry = part_geometry(pts, rot, filt.shape)
    expected = filt.expected_support(len(points))
    score = log_likelihood(
        points, geometry, expected, float(p.sigma), float(p.alpha), float(p.support_weight)
    )[0]
    return float(score) - (arm_collision_cost(state, filt.shape, p) if prior else 0.0)


def _torso_facing(filt: SkeletonFilter, points: np.ndarray, heading: float) -> np.ndarray:
    """The coarse torso search from one heading guess (radians), the limbs at rest;
    returns the pose."""
    centre = np.median(points[:, :2], axis=0)
    guess = rest_state(filt.shape, float(centre[0]), float(centre[1]), heading)
    spread = np.zeros(D)
    spread[:12] = _TORSO_SPREAD
    filt.reset(guess, spread)
    filt.anneal(points, "torso", int(filt.params.init_layers), spread, _TORSO_AND_LEGS)
    return filt.estimate.copy()


def initialise_facing(filt: SkeletonFilter, points: np.ndarray, heading: float) -> np.ndarray:
    """Coarse to fine from one heading guess (radians); returns the estimate."""
    p = filt.params
    layers = int(p.init_layers)
    filt.reset(_torso_facing(filt, points, heading))
    for name in LIMBS:
        search_limb(filt, points, name)
        for _ in range(_LIMB_TRIES - 1):  # again: the better of the searches is kept
            search_limb_again(filt, points, name)
    # The finer rounds: every partition again, from this estimate, as slow frames would.
    fine = motion_spread(p, _FINE_DT)
    for _ in range(_FINE_ROUNDS):
        filt.reset(filt.estimate, fine)
        for name in PARTITIONS:
            filt.anneal(points, name, layers, fine)
    return filt.estimate.copy()


def search_limb_again(
    filt: SkeletonFilter,
    points: np.ndarray,
    limb: str,
    particles: int | None = None,
    layers: int | None = None,
    margin: float | None = None,
) -> bool:
    """:func:`search_limb` from the current estimate, its pose kept only where the whole
    body's likelihood rose (with a ``margin``, also the likelihood without the arms'
    collision prior, by more than it: the data, not the prior alone, must prefer the new
    pose); the limb's particles then all take the estimate. The search anneals the first
    ``particles`` of them (None: all) over ``layers`` layers (None: ``init_layers``).
    Returns whether the limb moved."""
    dims = list(PARTITIONS[limb])
    before, kept = filt.estimate.copy(), filt.particles
    scores = _scores(filt, points, before)
    if particles is not None:
        filt.particles = kept[:particles].copy()
    search_limb(filt, points, limb, layers)
    filt.particles = kept
    moved = _better(scores, _scores(filt, points, filt.estimate), margin)
    if not moved:
        filt.estimate = before
    else:
        filt.stop_limb(dims)
    filt.particles[:, dims] = filt.estimate[dims]
    return moved


def swap_legs(filt: SkeletonFilter, points: np.ndarray, margin: float) -> bool:
    """Legs found the wrong way round: where the feet are close to the body's middle (a
    runner mid-stride seen by two sensors) a left leg on the right leg's points and a right
    leg on the left's, both thighs crossed, explain the cloud about as well as the true
    legs, and tracking does not undo it (each leg holds the points the other would take).
    Try the exchange: each leg bent (least squares on its four angles, within their limits)
    to put its knee and ankle where the other's are, both legs then annealed as a frame
    would; kept where the data's likelihood (without the arms' prior) rises by more than
    ``margin`` and the whole body's rises. Tried only where the knees are crossed or about
    level (the left knee less than ``_KNEES_APART`` to the left of the right one, along the
    hips' line): legs the right way round but crossed at the knees are rare. A refused
    exchange leaves the filter exactly as it was, its random numbers included. Returns
    whether the legs were exchanged."""
    before = filt.estimate.copy()
    joints = forward_kinematics(before, filt.shape)[0]
    hips = joints[POINTS.index("left_hip")] - joints[POINTS.index("right_hip")]
    knees = joints[POINTS.index("left_knee")] - joints[POINTS.index("right_knee")]
    if knees @ hips / max(float(np.linalg.norm(hips)), 1e-9) > _KNEES_APART:
        return False
    saved = filt.snapshot()
    scores = _scores(filt, points, before)
    swapped = before.copy()
    for leg, other in (("left", "right"), ("right", "left")):
        dims = list(PARTITIONS[f"{leg}_leg"])
        own = [POINTS.index(f"{leg}_knee"), POINTS.index(f"{leg}_ankle")]
        targets = joints[[POINTS.index(f"{other}_knee"), POINTS.index(f"{other}_ankle")]]
        start = before[list(PARTITIONS[f"{other}_leg"])]  # the mirror image
        swapped[dims] = _reach(filt.shape, before, dims, own, targets, start)
    fine = motion_spread(filt.params, _FINE_DT)
    filt.reset(swapped, fine)  # every particle near the exchange, as a frame would start
    for leg in ("left_leg", "right_leg"):
        filt.anneal(points, leg, int(filt.params.layers), fine)
    if _better(scores, _scores(filt, points, filt.estimate), margin):
        return True
    filt.restore(saved)
    return False


def turn_around(filt: SkeletonFilter, points: np.ndarray, margin: float) -> bool:
    """A body found facing backwards (left for right, front for back) explains a cloud
    seen by two sensors about as well as the true one, and tracking does not undo it where
    the person does not travel (``facing_speed`` cannot tell). Try it turned round: every
    joint put where its mirror image is (least squares on every number, within the
    limits, from the heading turned by half a turn and each limb starting from the other's
    angles), then both poses, as found and turned, refined alike (``_TURN_ROUNDS`` rounds of
    every partition over ``init_layers`` layers: a pose tracked for many frames against one
    just made is not a fair match). The turned one is kept where ``_better`` says so with
    ``margin``; else the filter is left exactly as it was, its random numbers included.
    Returns whether it turned."""
    before = filt.estimate.copy()
    joints = forward_kinematics(before, filt.shape)[0][: len(JOINTS)]
    start = before.copy()
    start[3] += np.pi
    for side, other in (("left", "right"), ("right", "left")):
        for limb in ("arm", "leg"):
            start[list(PARTITIONS[f"{side}_{limb}"])] = before[list(PARTITIONS[f"{other}_{limb}"])]
    start[_TURN_NEGATED] *= -1.0
    everything = list(range(D))
    turned = _reach(
        filt.shape, before, everything, everything[: len(JOINTS)], joints[_MIRROR], start,
        _TURN_EVALUATIONS,
    )  # fmt: skip
    saved = filt.snapshot()
    fine = motion_spread(filt.params, _FINE_DT)
    refined = []
    for pose in (before, turned):
        filt.estimate = pose
        for _ in range(_TURN_ROUNDS):
            filt.reset(filt.estimate, fine)
            filt.particles = filt.particles[:_TURN_PARTICLES]
            for name in PARTITIONS:
                filt.anneal(points, name, int(filt.params.init_layers), fine)
        refined.append((filt.estimate, _scores(filt, points, filt.estimate)))
    if _better(refined[0][1], refined[1][1], margin):
        filt.reset(refined[1][0])
        return True
    filt.restore(saved)
    return False


def _reach(
    shape: BodyShape,
    state: np.ndarray,
    dims: list[int],
    own: list[int],
    targets: np.ndarray,
    start: np.ndarray,
    evaluations: int | None = None,
) -> np.ndarray:
    """The angles ``dims`` of ``state`` that bring its points ``own`` nearest ``targets``
    (metres, least squares, within the angles' limits), from the angles ``start``, after
    at most ``evaluations`` evaluations of the kinematics (None: until it converges)."""
    low, high = LIMITS[dims, 0], LIMITS[dims, 1]

    def points(angles: np.ndarray) -> np.ndarray:  # (len(angles), len(own), 3)
        trials = np.repeat(state[None], len(angles), axis=0)
        trials[:, dims] = angles
        return forward_kinematics(trials, shape)[0][:, own]

    def residual(angles: np.ndarray) -> np.ndarray:
        return (points(angles[None])[0] - targets).ravel()

    def jacobian(angles: np.ndarray) -> np.ndarray:
        # Forward differences, every angle's step in one batch of the kinematics (which run
        # in float32: the step must stay well above its rounding); a step that would leave
        # the limits goes the other way.
        step = _DIFF_STEP * np.maximum(1.0, np.abs(angles))
        step[angles + step > high] *= -1.0
        moved = points(np.vstack([angles, angles + np.diag(step)]))
        return ((moved[1:] - moved[0]) / step[:, None, None]).reshape(len(dims), -1).T

    start = np.clip(start, low + 1e-6, high - 1e-6)
    return least_squares(
        residual, start, jac=jacobian, bounds=(low, high), xtol=1e-4, max_nfev=evaluations
    ).x


def _better(before: tuple[float, float], after: tuple[float, float], margin: float | None) -> bool:
    """Whether a new pose is kept: the whole body's likelihood rose and (with a
    ``margin``) the data's, without the arms' prior, by more than it; both pairs from
    :func:`_scores`."""
    return after[0] > before[0] and (margin is None or after[1] > before[1] + margin)


def _scores(filt: SkeletonFilter, points: np.ndarray, state: np.ndarray) -> tuple[float, float]:
    """:func:`pose_log_likelihood` of one pose with the arms' collision prior and without."""
    data = pose_log_likelihood(filt, points, state, prior=False)
    return data - arm_collision_cost(state, filt.shape, filt.params), data


def search_limb(
    filt: SkeletonFilter, points: np.ndarray, limb: str, layers: int | None = None
) -> None:
    """A limb's coarse search: angles drawn uniformly within its limits, annealed over
    ``layers`` layers (None: ``init_layers``) against the rest of the estimate."""
    dims = list(PARTITIONS[limb])
    low, high = LIMITS[dims, 0], LIMITS[dims, 1]
    n = len(filt.particles)
    filt.particles[:, dims] = filt.rng.uniform(low, high, size=(n, len(dims)))
    # A share near the limb at rest (an arm hanging, a leg straight): the likeliest pose,
    # which a few points at the body's side (an arm the trunk half hides) support.
    rest = int(n * _REST_SHARE)
    near = filt.rng.normal(size=(rest, len(dims))) * _REST_SPREAD + _REST[limb]
    filt.particles[:rest, dims] = np.clip(near, low, high)
    spread = np.zeros(D)
    spread[dims] = _LIMB_SPREAD
    layers = int(filt.params.init_layers) if layers is None else layers
    filt.anneal(points, limb, layers, spread)


def initialise(filt: SkeletonFilter, points: np.ndarray) -> np.ndarray:
    """Find a standing person's pose from nothing but their cloud (N, 3), world frame;
    leaves the filter's particles around it and returns it (D,): :func:`initialise_both_ways`'s
    pose."""
    return initialise_both_ways(filt, points)[0]


def initialise_both_ways(filt: SkeletonFilter, points: np.ndarray) -> tuple[np.ndarray, float]:
    """:func:`initialise`, and how much better the heading chosen explains the cloud than the
    other one: the full-body log-likelihoods' difference (0 where both scored alike).

    Both headings along the body's axis are completed and the full body's likelihood
    chooses, even where the feet seem sure: mid-stride they were wrong (the run clip,
    fusion and tracker seeds 1: 136 degrees off, 88 % of marker-frames lost). Then each
    arm is tried at rest (:func:`hang_arm`, with ``limb_research_margin``)."""
    points = np.asarray(points, dtype=np.float64)
    best_state, best_score = None, -np.inf
    headings, _ = facing_candidates(points, filt.shape, body_axis(filt, points))
    scores = []
    for heading in headings:
        state = initialise_facing(filt, points, heading)
        scores.append(pose_log_likelihood(filt, points, state))
        if scores[-1] > best_score:
            best_state, best_score = state, scores[-1]
    filt.reset(best_state)
    margin = float(filt.params.limb_research_margin)
    for arm in ("left_arm", "right_arm"):
        hang_arm(filt, points, arm, margin)
    return filt.estimate.copy(), float(best_score - min(scores))


def hang_arm(filt: SkeletonFilter, points: np.ndarray, arm: str, margin: float) -> bool:
    """An arm the data do not place is put at rest. With two sensors an arm the trunk
    hides, or one lying on the head's or the chest's points, is held wherever the search
    left it (the walk clip with two sensors: a wrist folded overhead, 0.7-0.9 m off, for
    the rest of the clip), and hanging at the side is the likeliest pose of an arm not
    seen. So the arm is put at rest and annealed from there (:func:`_arm_from_rest`), and that
    pose is kept unless the pose found explains the data better by ``margin`` (``_better``,
    the found pose in the place of a new one: here the burden of proof is on the found
    pose). A raised arm that is seen keeps its place: hanging, its points go unexplained.
    Where the found pose stays, the filter is left exactly as it was, its random numbers
    included. Returns whether the arm was put at rest."""
    found, saved = filt.estimate.copy(), filt.snapshot()
    _arm_from_rest(filt, points, arm)
    if not _better(_scores(filt, points, filt.estimate), _scores(filt, points, found), margin):
        filt.reset(filt.estimate)
        return True
    filt.restore(saved)
    return False


def rest_arm_again(
    filt: SkeletonFilter,
    points: np.ndarray,
    arm: str,
    gain: float,
    slack: float,
    particles: int = _HANG_PARTICLES,
    layers: int | None = None,
) -> bool:
    """While tracking, :func:`hang_arm` the other way round: the arm annealed from rest is
    kept only where the whole body's likelihood (with the arms' collision prior) rises by
    more than ``gain`` and the data's (without it) falls by no more than ``slack``. An arm
    the search put on points the trunk or the head explain (folded through the chest or
    along the head: the prior's cost) goes back to hanging, which the data like as well;
    an arm the data place stays (at rest, its points go unexplained). The limb's particles
    then all take the estimate and its velocity is forgotten; where the arm stays, the
    filter is left exactly as it was, its random numbers included. Returns whether the
    arm was put at rest. The arm is annealed from rest over ``particles`` particles and
    ``layers`` layers (None: ``init_layers``)."""
    found, saved = filt.estimate.copy(), filt.snapshot()
    rest = _arm_from_rest(filt, points, arm, particles, layers)
    filt.restore(saved)
    before, after = _scores(filt, points, found), _scores(filt, points, rest)
    if not (after[0] > before[0] + gain and after[1] > before[1] - slack):
        return False
    dims = list(PARTITIONS[arm])
    filt.estimate[dims] = rest[dims]
    filt.stop_limb(dims)
    filt.particles[:, dims] = rest[dims]
    return True


def _arm_from_rest(
    filt: SkeletonFilter,
    points: np.ndarray,
    arm: str,
    particles: int = _HANG_PARTICLES,
    layers: int | None = None,
) -> np.ndarray:
    """The arm put at rest and annealed from there (``layers`` layers, None: ``init_layers``,
    over ``particles`` particles, the rest of the body fixed); leaves the filter's particles
    there and returns its estimate."""
    dims = list(PARTITIONS[arm])
    rest = filt.estimate.copy()
    rest[dims] = _REST[arm]
    spread = np.zeros(D)
    spread[dims] = _REST_SPREAD
    filt.reset(rest, spread)
    filt.particles = filt.particles[:particles]
    layers = int(filt.params.init_layers) if layers is None else layers
    filt.anneal(points, arm, layers, spread)
    return filt.estimate.copy()
