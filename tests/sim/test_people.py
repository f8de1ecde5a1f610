"""Simulated people: humanoid bodies, gait, behaviours, collision avoidance, determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import write_scenario

from optrack.sim import Simulation, load_scenario
from optrack.sim.body import JOINTS, TRUTH_JOINTS
from optrack.sim.crowd import EnterLeave, Follow, Route, Stand, Wander


def _walk(sim: Simulation, seconds: float, rate: float = 10.0):
    """Ground truth (no visibility) every 1/rate s."""
    return [sim.truth(sim.snapshot(t), visibility=False) for t in np.arange(0.0, seconds, 1 / rate)]


def test_twelve_people_walk_at_once_without_walking_into_each_other():
    sim = Simulation("mixed", seed=4, people=12, seconds=12.0)
    closest = math.inf
    counts = []
    for truth in _walk(sim, 12.0):
        counts.append(len(truth.people))
        xy = np.array([[p.x, p.y] for p in truth.people])
        distance = np.linalg.norm(xy[:, None] - xy[None], axis=2)
        np.fill_diagonal(distance, np.inf)
        closest = min(closest, float(distance.min()))
    assert max(counts) >= 11  # twelve, less whoever has not entered yet or has left
    assert closest >= 0.35


def test_people_keep_out_of_furniture_and_inside_the_room():
    sim = Simulation("mixed", seed=2, people=8, seconds=15.0)
    venue = sim.venue
    for truth in _walk(sim, 15.0, rate=5.0):
        xy = np.array([[p.x, p.y] for p in truth.people])
        assert np.all(venue.clearance(xy) > 0.0)


def test_heights_are_adult_or_child_ranges_and_truth_is_the_head_top():
    sim = Simulation("crowd", seed=1, people=20, seconds=2.0)
    heights = np.array([p.height for p in sim.crowd.people])
    assert heights.min() >= 1.5 and heights.max() <= 2.0
    truth = sim.truth(sim.snapshot(1.0), visibility=False)
    for person in truth.people:
        standing = sim.crowd.people[person.id].height
        assert 0.95 * standing <= person.height <= standing + 1e-6

    scenario = load_scenario("crowd")
    import msgspec

    kids = msgspec.structs.replace(
        scenario, people=msgspec.structs.replace(scenario.people, children=1.0)
    )
    sim = Simulation(kids, seed=1, people=10)
    heights = np.array([p.height for p in sim.crowd.people])
    assert heights.min() >= 0.8 and heights.max() <= 1.4


def test_walking_people_swing_legs_and_arms_in_opposition(tmp_path):
    data = {
        "venue": {"size": [12.0, 6.0]},
        "sensors": {"count": 1},
        "people": {"count": 1, "routes": [[[-5.0, 0.0], [5.0, 0.0]]]},
    }
    sim = Simulation(load_scenario(write_scenario(tmp_path / "walk.yaml", data)), seed=0)
    legs, arms = [], []
    for t in np.arange(1.0, 4.0, 0.02):
        state = sim.snapshot(t)
        joints = state.joints[0]
        heading = state.crowd.pose.heading[0]
        forward = np.array([math.cos(heading), math.sin(heading), 0.0])
        pelvis = joints[JOINTS.index("pelvis")]
        legs.append((joints[JOINTS.index("left_ankle")] - pelvis) @ forward)
        arms.append((joints[JOINTS.index("left_wrist")] - pelvis) @ forward)
    legs, arms = np.array(legs), np.array(arms)
    assert np.ptp(legs) > 0.3  # a stride, not a shuffle
    assert np.ptp(arms) > 0.1
    assert np.corrcoef(legs, arms)[0, 1] < -0.5  # left arm forward when the left leg is back


def test_behaviours_include_standing_groups_crossing_and_doors():
    sim = Simulation("mixed", seed=0, people=6)
    kinds = {type(p.behaviour) for p in sim.crowd.people}
    assert {Stand, Follow, Route, EnterLeave, Wander} <= kinds


def test_standing_person_stays_put_and_group_members_stay_together():
    sim = Simulation("mixed", seed=0, people=6, seconds=15.0)
    people = sim.crowd.people
    stand = next(i for i, p in enumerate(people) if isinstance(p.behaviour, Stand))
    follower = next(i for i, p in enumerate(people) if isinstance(p.behaviour, Follow))
    leader = people[follower].behaviour.leader
    start = None
    gaps = []
    for t in np.arange(0.0, 15.0, 0.5):
        sim.snapshot(t)
        if start is None:
            start = sim.crowd.pos[stand].copy()
        assert np.linalg.norm(sim.crowd.pos[stand] - start) < 0.5
        gaps.append(np.linalg.norm(sim.crowd.pos[follower] - sim.crowd.pos[leader]))
    assert np.median(gaps) < 1.5


def test_people_enter_through_a_door_and_leave_again():
    sim = Simulation("mixed", seed=0, people=6, seconds=20.0)
    index = next(i for i, p in enumerate(sim.crowd.people) if isinstance(p.behaviour, EnterLeave))
    behaviour = sim.crowd.people[index].behaviour
    present = []
    for truth in _walk(sim, 20.0, rate=4.0):
        present.append((truth.t, any(p.id == index for p in truth.people)))
    times = [t for t, here in present if here]
    assert times, "the visitor never came in"
    assert min(times) >= behaviour.enter - 0.3
    assert not present[-1][1], "the visitor never left"


def test_crossing_pair_paths_intersect():
    sim = Simulation("mixed", seed=0, people=6)
    routes = [p.behaviour.points for p in sim.crowd.people if isinstance(p.behaviour, Route)]
    assert len(routes) == 2
    (a0, a1), (b0, b1) = routes

    def side(p, q, r):
        u, v = q - p, r - p
        return np.sign(u[0] * v[1] - u[1] * v[0])

    assert side(a0, a1, b0) != side(a0, a1, b1) and side(b0, b1, a0) != side(b0, b1, a1)


def test_truth_has_every_joint_of_every_person():
    sim = Simulation("crowd", seed=0, seconds=1.0)
    truth = sim.truth(sim.snapshot(0.5))
    assert len(truth.people) == 7
    for person in truth.people:
        assert set(person.joints) == set(TRUTH_JOINTS)
        head = np.array(person.joints["head"])
        ankle = np.array(person.joints["left_ankle"])
        assert head[2] - ankle[2] > 1.0
        assert set(person.visible) == {s.id for s in sim.sensors}


def test_same_seed_same_motion_other_seed_other_motion():
    a = _walk(Simulation("mixed", seed=5, seconds=5.0), 5.0, rate=2.0)
    b = _walk(Simulation("mixed", seed=5, seconds=5.0), 5.0, rate=2.0)
    c = _walk(Simulation("mixed", seed=6, seconds=5.0), 5.0, rate=2.0)
    assert a == b
    assert a != c


@pytest.mark.parametrize(
    "name", ["crowd", "distance", "occlusions", "calibration", "refinement", "mixed"]
)
def test_every_scenario_runs_for_a_second(name):
    sim = Simulation(name, seed=0, seconds=1.0)
    for t in (0.0, 0.5, 0.99):
        truth = sim.truth(sim.snapshot(t))
        assert all(0.0 <= v <= 1.0 for p in truth.people for v in p.visible.values())
