"""The mocap scenario end to end: rendered depth and body-part labels of a mocap person
land on their true joints; the recording's ground truth holds every joint and angle;
``optrack sim mocap --clip``."""

from __future__ import annotations

import contextlib
import io
import json

import msgspec
import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from optrack.cli import main
from optrack.geometry import transform_points
from optrack.recording import Recording
from optrack.recording.format import PersonTruth
from optrack.sim import Simulation, load_scenario
from optrack.sim.articulated import ArticulatedPose, forward_kinematics
from optrack.sim.body import CYLINDERS, JOINTS, PART_NAMES
from optrack.sim.recorder import write_recording
from optrack.skeleton.joints import JOINTS as SKELETON_JOINTS
from optrack.skeleton.joints import PARENT

CLIP = "cmu_16_27_walk_turn_left.bvh"


def _segment_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    axis = b - a
    s = np.clip((points - a) @ axis / max(axis @ axis, 1e-12), 0.0, 1.0)
    return np.linalg.norm(points - (a + s[:, None] * axis), axis=1)


def _surface_points(sim: Simulation, state, sensor: int = 0):
    """World points and part labels of the pixels where the sensor sees person 0."""
    result = sim.renderer(sensor, ("depth",)).render(state.geometry)
    rows, cols = np.nonzero(result.labels == 0)
    k = sim.sensors[sensor].model.intrinsics
    z = result.depth[rows, cols]
    camera = np.stack([(cols - k.cx) / k.fx * z, (rows - k.cy) / k.fy * z, z], axis=1)
    return transform_points(sim.sensors[sensor].world_T_camera, camera), result.parts[rows, cols]


def test_rendered_depth_of_a_mocap_person_lands_on_its_joints(shared_data, tmp_path):
    scenario = load_scenario("mocap")
    path = tmp_path / "one.yaml"
    data = {
        "seconds": 2.0,
        "venue": {"size": [7.0, 6.0]},
        "sensors": {"count": 1, "poses": [{"at": [-3.2, 0.0, 2.2], "look_at": [0.0, 0.0, 0.9]}]},
        "people": {"count": 1, "shapes": "varied", "area": [-1.0, -1.0, 1.0, 1.0]},
    }
    path.write_text(yaml.safe_dump(data))
    sim = Simulation(path, seed=5, clips=[str(shared_data / "mocap" / CLIP)])
    assert scenario.people.shapes == "varied"
    for t in (0.4, 1.3):
        state = sim.snapshot(t)
        truth = sim.truth(state, visibility=False).people[0]
        points, parts = _surface_points(sim, state)
        assert len(points) > 2000
        # Every seen point lies on the skeleton of the truth: within a limb's girth of
        # one of its bones (the head: of the head joint).
        joints = {name: np.array(xyz) for name, xyz in truth.joints.items()}
        bones = [
            _segment_distance(points, joints[PARENT[j]], joints[j]) for j in SKELETON_JOINTS[1:]
        ]
        nearest = np.min(bones, axis=0)
        # The feet reach past the ankle, the last joint (up to 0.2 m to the toes): their
        # points are checked against their own part below.
        feet = np.isin(parts, [PART_NAMES.index("left_foot"), PART_NAMES.index("right_foot")])
        nearest = nearest[~feet]
        assert np.percentile(nearest, 99) < 0.16 and np.median(nearest) < 0.08
        # Each labelled pixel lies on its own part, within that person's radii of it.
        shape = state.shapes[0]
        full = state.joints[0]
        for c, part in enumerate(CYLINDERS):
            mine = parts == PART_NAMES.index(part.name)
            if mine.sum() < 10:
                continue
            a, b = full[JOINTS.index(part.a)], full[JOINTS.index(part.b)]
            distance = _segment_distance(points[mine], a, b)
            assert distance.max() < shape.radii[c].max() * 1.05 + 0.005, part.name
        head = parts == PART_NAMES.index("head")
        assert head.sum() > 20
        distance = np.linalg.norm(points[head] - full[JOINTS.index("head")], axis=1)
        assert distance.max() < shape.head.max() + 0.005
        assert set(np.unique(parts)) <= set(range(len(PART_NAMES)))


def test_the_mocap_scenario_writes_joint_truth(shared_data, tmp_path):
    sim = Simulation(
        "mocap", seed=1, people=2, sensors=2, seconds=1.0, clips=[str(shared_data / "mocap" / CLIP)]
    )
    write_recording(sim, tmp_path / "rec", noise=False, instants=[0.2, 0.6])
    truths = list(Recording(tmp_path / "rec").ground_truth())
    assert len(truths) >= 2
    for truth in truths:
        assert len(truth.people) == 2
        for person in truth.people:
            assert list(person.joints) == list(SKELETON_JOINTS)
            assert list(person.angles) == list(SKELETON_JOINTS)
            assert np.isfinite([v for xyz in person.joints.values() for v in xyz]).all()
            assert 1.4 < person.height < 2.1
            assert person.visible  # per-sensor visible fractions, as for any person
            # The angles are the state: with the person's bones they give the joints.
            shape = sim.body.shape(person.id, sim.crowd.people[person.id].height)
            local = np.broadcast_to(np.eye(3), (1, len(JOINTS), 3, 3)).copy()
            local[0, : len(SKELETON_JOINTS)] = Rotation.from_rotvec(
                list(person.angles.values())
            ).as_matrix()
            pose = ArticulatedPose(np.array([person.joints["pelvis"]]), local)
            positions, _ = forward_kinematics(shape.offsets[None], pose)
            expected = np.array(list(person.joints.values()))
            assert positions[0, : len(SKELETON_JOINTS)] == pytest.approx(expected, abs=2e-3)


def test_optrack_sim_mocap_with_a_clip(shared_data, tmp_path):
    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout):
        code = main(
            [
                "sim",
                "mocap",
                "--clip",
                str(shared_data / "mocap" / "cmu_131_02_alt_naming.bvh"),
                "--out",
                str(tmp_path / "rec"),
                "--sensors",
                "2",
                "--people",
                "1",
                "--seconds",
                "0.1",
                "--json",
            ]
        )
    assert code == 0
    result = json.loads(stdout.getvalue())
    assert result["scenario"] == "mocap" and result["sensors"] == 2 and result["people"] == 1
    truth = next(Recording(tmp_path / "rec").ground_truth())
    assert set(truth.people[0].joints) == set(SKELETON_JOINTS)


def test_a_bad_clip_on_the_command_line_is_one_line(tmp_path, capsys):
    code = main(["sim", "mocap", "--clip", str(tmp_path / "x.bvh"), "--out", str(tmp_path / "r")])
    assert code != 0
    err = capsys.readouterr().err.strip()
    assert "does not exist" in err and "Traceback" not in err and err.count("\n") == 0


def test_old_recordings_joint_names_read_as_todays():
    line = {
        "id": 3,
        "x": 0,
        "y": 0,
        "height": 1.7,
        "joints": {"wrist_l": [1, 2, 3], "knee_r": [0, 0, 0.5]},
    }
    person = msgspec.json.decode(json.dumps(line).encode(), type=PersonTruth)
    assert person.joints == {"left_wrist": (1.0, 2.0, 3.0), "right_knee": (0.0, 0.0, 0.5)}
    assert person.angles == {}
