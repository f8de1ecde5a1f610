"""Articulated people driven by real motion capture (../shared/data/mocap) and by the
procedural motions: retargeting keeps each person's own bones, clips loop without a
jump, the reference frame is skipped, procedural behaviours do what they say."""

from __future__ import annotations

import math

import msgspec
import numpy as np
import pytest

from optrack.errors import UserError
from optrack.sim import Simulation, load_scenario
from optrack.sim.body import JOINTS, BodyShape
from optrack.sim.bvh import BVH_TO_WORLD, map_joints, read_bvh
from optrack.sim.mocap import BODY_CLEARANCE, Performance, retarget

BONES = (
    ("left_hip", "left_knee"),
    ("left_knee", "left_ankle"),
    ("right_shoulder", "right_elbow"),
    ("right_elbow", "right_wrist"),
    ("spine", "neck"),
)


def _joint(state, name: str) -> np.ndarray:
    return state.joints[:, JOINTS.index(name)]


def _knee_angle(thigh: np.ndarray, shin: np.ndarray) -> np.ndarray:
    cos = (
        np.sum(thigh * shin, axis=-1)
        / np.linalg.norm(thigh, axis=-1)
        / np.linalg.norm(shin, axis=-1)
    )
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def test_retargeting_keeps_each_persons_own_limbs_and_the_clips_angles(shared_data):
    path = shared_data / "mocap" / "cmu_13_30_jumping_jacks_excerpt.bvh"
    sim = Simulation("mocap", seed=3, people=3, seconds=1.0, clips=[str(path)])
    clip = read_bvh(path)
    lengths = []
    for t in np.arange(0.0, 0.9, 0.1):
        state = sim.snapshot(t)
        lengths.append(
            [np.linalg.norm(_joint(state, b) - _joint(state, a), axis=1) for a, b in BONES]
        )
        # Person 0 plays from the clip's start (frame 1: frame 0 is the reference pose).
        frame = 1 + int(round(t / clip.frame_time))
        positions, _ = clip.forward_kinematics(slice(frame, frame + 1))
        mapped = map_joints(clip).joints
        thigh = positions[0, mapped["left_knee"]] - positions[0, mapped["left_hip"]]
        shin = positions[0, mapped["left_ankle"]] - positions[0, mapped["left_knee"]]
        ours = _knee_angle(
            _joint(state, "left_knee")[0] - _joint(state, "left_hip")[0],
            _joint(state, "left_ankle")[0] - _joint(state, "left_knee")[0],
        )
        assert ours == pytest.approx(_knee_angle(thigh, shin), abs=0.05)
    lengths = np.array(lengths)  # (instants, bones, people)
    assert np.ptp(lengths, axis=0).max() < 1e-9  # rigid bones, whatever the clip does
    for k, index in enumerate(state.crowd.index):
        shape = sim.body.shape(int(index), sim.crowd.people[int(index)].height)
        for b, (_, child) in enumerate(BONES):
            assert lengths[0, b, k] == pytest.approx(
                np.linalg.norm(shape.offsets[JOINTS.index(child)])
            )
    thighs = lengths[0, 0]
    assert np.ptp(thighs) > 0.005  # everyone their own legs
    heights = [sim.crowd.people[int(i)].height for i in state.crowd.index]
    assert np.ptp(thighs / heights) > 0.002  # and their own proportions, not just scaled


def test_the_reference_pose_is_skipped(shared_data):
    clip = read_bvh(shared_data / "mocap" / "cmu_16_27_walk_turn_left.bvh")
    motion = retarget(clip)
    assert len(motion.local) == clip.frame_count - 1
    mapped = map_joints(clip).joints
    positions, _ = clip.forward_kinematics(slice(1, 2))
    hips = (positions[0, mapped["left_hip"]] + positions[0, mapped["right_hip"]]) / 2
    assert motion.hips[0] == pytest.approx(hips @ BVH_TO_WORLD.T * 0.0254 / 0.45)
    squat = read_bvh(shared_data / "mocap" / "cmu_13_30_squat_excerpt.bvh")
    assert len(retarget(squat).local) == squat.frame_count  # no reference pose to skip


def test_a_short_clip_loops_from_where_it_ended_without_a_jump(shared_data):
    """The run (1.43 s) over 4 s: at each loop the hips go on from the last frame's
    position and heading, no joint moves more in a step than it does anywhere else, and
    a turn between loops keeps the clip's pace (it turns where the runner goes next; it
    once swung the path already run round, the hips at twice a jog's speed)."""
    path = shared_data / "mocap" / "cmu_02_03_run.bvh"
    sim = Simulation("mocap", seed=0, people=1, seconds=4.0, clips=[str(path)])
    performer = sim.crowd.people[0].behaviour
    assert isinstance(performer, Performance)
    period = performer.motion.period
    rate = 240.0
    times = np.arange(0.0, 4.0, 1 / rate)
    joints = np.array([sim.snapshot(t).joints[0] for t in times])  # (T, J, 3)
    steps = np.linalg.norm(np.diff(joints, axis=0), axis=2).max(axis=1)
    at_loop = np.floor(times[1:] / period) != np.floor(times[:-1] / period)
    assert at_loop.sum() == 2  # two loop boundaries within 4 s
    assert steps[at_loop].max() <= 1.2 * steps[~at_loop].max()
    # The hips' path and heading carry on across each boundary.
    pelvis = joints[:, JOINTS.index("pelvis"), :2]
    hip_line = joints[:, JOINTS.index("left_hip"), :2] - joints[:, JOINTS.index("right_hip"), :2]
    heading = np.unwrap(np.arctan2(hip_line[:, 1], hip_line[:, 0]))
    speed = np.linalg.norm(np.diff(pelvis, axis=0), axis=1) * rate
    for k in np.flatnonzero(at_loop):
        assert np.linalg.norm(pelvis[k + 1] - pelvis[k]) * rate < 1.2 * speed[~at_loop].max()
        assert abs(heading[k + 1] - heading[k]) < math.radians(3)
    assert speed.sum() / rate > 3.0  # it ran on (in the room)
    clip = np.linalg.norm(np.diff(performer.motion.hips[:, :2], axis=0), axis=1)
    clip_speed = clip.max() / performer.motion.frame_time * performer.scale
    assert speed.max() < 1.1 * clip_speed
    turns = [loop.turn for loop in performer.loops[1:3]]
    assert any(turn != 0.0 for turn in turns)  # the room made it turn
    assert np.all(sim.venue.clearance(pelvis) > 0.25)


def test_procedural_motions_on_the_same_state():
    def run(clip: str, seconds: float, rate: float = 20.0):
        sim = Simulation("mocap", seed=1, people=1, seconds=seconds, clips=[clip])
        states = [sim.snapshot(t) for t in np.arange(0.0, seconds, 1 / rate)]
        return sim, np.array([s.joints[0] for s in states]), states

    sim, joints, states = run("wave", 4.0)
    wrist, head = joints[:, JOINTS.index("right_wrist"), 2], joints[:, JOINTS.index("head"), 2]
    assert (wrist > head).mean() > 0.4 and wrist[0] < joints[0, JOINTS.index("pelvis"), 2]

    sim, joints, states = run("crouch", 3.6)
    pelvis = joints[:, JOINTS.index("pelvis"), 2]
    assert pelvis.min() < pelvis[0] - 0.3
    ankles = joints[:, [JOINTS.index("left_ankle"), JOINTS.index("right_ankle")]]
    assert np.ptp(ankles[..., 2], axis=0).max() < 0.01  # feet stay on the floor...
    assert np.linalg.norm(ankles[..., :2] - ankles[:1, :, :2], axis=2).max() < 0.03  # ...and put

    sim, joints, states = run("turn", 4.0)
    hips = joints[:, JOINTS.index("left_hip"), :2] - joints[:, JOINTS.index("right_hip"), :2]
    heading = np.unwrap(np.arctan2(hips[:, 1], hips[:, 0]))
    assert math.degrees(heading[-1] - heading[0]) == pytest.approx(90 * 3.95 / 2, abs=6)
    pelvis = joints[:, JOINTS.index("pelvis"), :2]
    assert np.linalg.norm(pelvis - pelvis[0], axis=1).max() < 0.15  # on the spot

    sim, joints, states = run("walk", 2.0)
    pelvis = joints[:, JOINTS.index("pelvis"), :2]
    travelled = np.linalg.norm(np.diff(pelvis, axis=0), axis=1).sum() / (len(pelvis) - 1) * 20
    scale = (
        sim.body.shape(0, sim.crowd.people[0].height).leg_length
        / BodyShape.standard(1.72).leg_length
    )
    assert travelled == pytest.approx(sim.body.params.full_gait_speed * scale, rel=0.15)


def test_an_unknown_clip_is_one_sentence(tmp_path):
    with pytest.raises(UserError, match="neither a BVH file") as error:
        Simulation("mocap", people=1, clips=["dance"])
    assert str(error.value).count(". ") == 0
    with pytest.raises(UserError, match="does not exist"):
        Simulation("mocap", people=1, clips=[str(tmp_path / "none.bvh")])


def test_people_have_shapes_of_their_own_only_where_asked():
    varied = Simulation("mocap", seed=2, people=3, seconds=1.0)
    standard = Simulation("mixed", seed=2, people=3, seconds=1.0)
    shapes = [varied.body.shape(i, 1.75) for i in range(3)]
    assert np.ptp([s.radii[8, 0] for s in shapes]) > 0.002  # thighs of other girths
    assert all(s.radii[8, 2] < s.radii[8, 0] for s in shapes)  # tapering to the knee
    plain = standard.body.shape(0, 1.75)
    assert plain.radii[8, 2] == plain.radii[8, 0]  # the standard: straight cylinders
    for shape in shapes + [plain]:
        state_height = shape.offsets[[0, 1, 2, 3], 2].sum() + shape.head[2]
        assert state_height == pytest.approx(1.75)  # everyone keeps their height


def test_the_same_seed_gives_the_same_performance(shared_data):
    clip = str(shared_data / "mocap" / "cmu_01_01_jumps_turnaround.bvh")
    first, second = (
        Simulation("mocap", seed=7, people=2, seconds=3.0, clips=[clip, "wave"]) for _ in range(2)
    )
    for t in (0.0, 1.1, 2.9):
        a = first.truth(first.snapshot(t), visibility=False)
        assert a == second.truth(second.snapshot(t), visibility=False)
    other = Simulation("mocap", seed=8, people=2, seconds=3.0, clips=[clip, "wave"])
    assert other.truth(other.snapshot(2.9), visibility=False) != a


def test_a_runner_stays_in_a_small_area_at_the_clips_pace(shared_data):
    """Placed in a 2.4 m square (the skeleton bench's, where three sensors see), the run
    (3.5 m/s at most, 1.43 s a play) turns at legs of its plays to stay inside, and its
    hips never go faster than the clip's own."""
    scenario = load_scenario("mocap")
    area = (-1.2, -1.2, 1.2, 1.2)
    scenario = msgspec.structs.replace(
        scenario, people=msgspec.structs.replace(scenario.people, area=area)
    )
    clip = str(shared_data / "mocap" / "cmu_02_03_run.bvh")
    sim = Simulation(scenario, people=1, sensors=3, seconds=4.0, clips=[clip], seed=1)
    performer = sim.crowd.people[0].behaviour
    assert performer.legs >= 2 and performer.leg < 0.8  # a play has legs that can turn
    rate = 120.0
    hips = performer.path(np.arange(0.0, 4.0, 1 / rate))
    assert np.all(np.abs(hips) <= 1.2 + 0.05)
    speed = np.linalg.norm(np.diff(hips, axis=0), axis=1) * rate
    own = np.linalg.norm(np.diff(performer.motion.hips[:, :2], axis=0), axis=1)
    assert speed.max() <= own.max() / performer.motion.frame_time * performer.scale * 1.01
    assert speed.sum() / rate > 8.0  # it ran all the time, turning


def test_three_runners_keep_off_the_walls_and_near_their_area(shared_data):
    """Three people running the same clip for 20 s (the second and third start into it,
    past its first legs) in the mocap room: every hips path keeps BODY_CLEARANCE from the
    walls and furniture, and stays within 0.3 m of the scenario's area."""
    clip = str(shared_data / "mocap" / "cmu_02_03_run.bvh")
    sim = Simulation("mocap", people=3, seconds=20.0, clips=[clip], seed=1)
    area = np.asarray(load_scenario("mocap").people.area)
    times = np.arange(0.0, 20.0, 0.05)
    for person in sim.crowd.people:
        hips = person.behaviour.path(times)
        assert sim.venue.clearance(hips).min() >= BODY_CLEARANCE - 1e-6
        outside = np.maximum(np.maximum(area[:2] - hips, hips - area[2:]), 0.0)
        assert outside.max() < 0.3
    assert max(p.behaviour.offset for p in sim.crowd.people) > sim.crowd.people[0].behaviour.leg
