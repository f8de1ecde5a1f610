"""The BVH reader against real CMU clips (../shared/data/mocap): frame counts, joint
names, a joint position worked out by hand, line endings, joint-name conventions,
units and the refusal of unknown skeletons."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from optrack.errors import UserError
from optrack.sim.bvh import (
    CMU_METRES_PER_UNIT,
    map_joints,
    metres_per_unit,
    read_bvh,
)
from optrack.skeleton.joints import JOINTS

CMU_JOINTS = (
    "Hips LHipJoint LeftUpLeg LeftLeg LeftFoot LeftToeBase RHipJoint RightUpLeg RightLeg "
    "RightFoot RightToeBase LowerBack Spine Spine1 Neck Neck1 Head LeftShoulder LeftArm "
    "LeftForeArm LeftHand LeftFingerBase LeftHandIndex1 LThumb RightShoulder RightArm "
    "RightForeArm RightHand RightFingerBase RightHandIndex1 RThumb"
).split()
ALT_JOINTS = (
    "Hips LHipJoint LeftHip LeftKnee LeftAnkle LeftToe RHipJoint RightHip RightKnee RightAnkle "
    "RightToe lowerback Chest Chest2 lowerneck Neck Head LeftCollar LeftShoulder LeftElbow "
    "LeftWrist lhand LFingers LThumb RightCollar RightShoulder RightElbow RightWrist rhand "
    "RFingers RThumb"
).split()


@pytest.fixture(scope="module")
def mocap(shared_data) -> Path:
    return shared_data / "mocap"


def _rz_ry_rx(z: float, y: float, x: float) -> np.ndarray:
    """R = Rz Ry Rx from degrees, written out (independent of the reader)."""
    z, y, x = (math.radians(v) for v in (z, y, x))
    rz = np.array([[math.cos(z), -math.sin(z), 0], [math.sin(z), math.cos(z), 0], [0, 0, 1]])
    ry = np.array([[math.cos(y), 0, math.sin(y)], [0, 1, 0], [-math.sin(y), 0, math.cos(y)]])
    rx = np.array([[1, 0, 0], [0, math.cos(x), -math.sin(x)], [0, math.sin(x), math.cos(x)]])
    return rz @ ry @ rx


def test_a_cmu_clip_has_its_frames_joints_and_frame_time(mocap):
    clip = read_bvh(mocap / "cmu_16_27_walk_turn_left.bvh")
    assert clip.frame_count == 244
    assert clip.frame_time == pytest.approx(0.0083333)
    assert clip.names == CMU_JOINTS
    assert clip.frames.shape == (244, 96)
    assert sum(j.end_site is not None for j in clip.joints) == 7
    assert clip.starts_with_reference_pose()  # frame 0: round numbers, -21 ... 21


def test_a_joint_position_worked_out_by_hand(mocap):
    """The left knee (LeftLeg) at frame 100: root position plus Hips, LHipJoint and
    LeftUpLeg rotations (Z, Y, X) applied to the offsets read off the file."""
    path = mocap / "cmu_16_27_walk_turn_left.bvh"
    lines = path.read_text().replace("\r", "").split("\n")
    values = [float(v) for v in lines[lines.index("MOTION") + 3 + 100].split()]
    hips = _rz_ry_rx(*values[3:6])
    hip_joint = hips @ _rz_ry_rx(*values[6:9])
    up_leg = hip_joint @ _rz_ry_rx(*values[9:12])
    left_hip = np.array(values[:3]) + hip_joint @ [1.57358, -1.76629, 0.73362]
    left_knee = left_hip + up_leg @ [2.40600, -6.61045, 0.0]
    assert left_knee == pytest.approx([-8.54200141, 7.81080097, -6.28660658], abs=1e-6)

    clip = read_bvh(path)
    positions, _ = clip.forward_kinematics(slice(100, 101))
    assert positions[0, clip.index("LeftUpLeg")] == pytest.approx(left_hip, abs=1e-9)
    assert positions[0, clip.index("LeftLeg")] == pytest.approx(left_knee, abs=1e-9)


def test_mixed_line_endings_and_the_other_naming(mocap):
    raw = (mocap / "cmu_131_02_alt_naming.bvh").read_bytes()
    assert b"\r\n" in raw and raw.count(b"\n") > raw.count(b"\r\n")  # both endings
    clip = read_bvh(mocap / "cmu_131_02_alt_naming.bvh")
    assert clip.frame_count == 1247 and clip.names == ALT_JOINTS
    assert not clip.starts_with_reference_pose()


def test_both_naming_conventions_map_onto_our_joints(mocap):
    cmu = read_bvh(mocap / "cmu_16_27_walk_turn_left.bvh")
    alt = read_bvh(mocap / "cmu_131_02_alt_naming.bvh")
    cmu_map, alt_map = map_joints(cmu), map_joints(alt)
    assert set(cmu_map.joints) == set(alt_map.joints) == set(JOINTS)
    names = {ours: cmu.names[i] for ours, i in cmu_map.joints.items()}
    alt_names = {ours: alt.names[i] for ours, i in alt_map.joints.items()}
    assert (names["left_hip"], names["left_knee"], names["left_ankle"]) == (
        "LeftUpLeg",
        "LeftLeg",
        "LeftFoot",
    )
    assert (alt_names["left_hip"], alt_names["left_knee"], alt_names["left_ankle"]) == (
        "LeftHip",
        "LeftKnee",
        "LeftAnkle",
    )
    # The shoulder joint proper, not the collar bone, in both.
    assert names["right_shoulder"] == "RightArm" and alt_names["right_shoulder"] == "RightShoulder"
    assert names["neck"] == "Neck" and alt_names["neck"] == "lowerneck"
    assert cmu.names[cmu_map.hand_tips["left"]] == "LeftHandIndex1"
    assert alt.names[alt_map.hand_tips["right"]] == "RFingers"
    jumps = read_bvh(mocap / "cmu_01_01_jumps_turnaround.bvh")  # LFingers for LeftHandIndex1
    assert jumps.names[map_joints(jumps).hand_tips["left"]] == "LFingers"


def _tiny(names: list[str], frames: str, lines: str = "\n") -> str:
    """A BVH text: a root and a chain of joints, each 10 units below the last."""
    text = ["HIERARCHY", f"ROOT {names[0]}", "{", "OFFSET 0 0 0"]
    text.append("CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation")
    for name in names[1:]:
        text += [f"JOINT {name}", "{", "OFFSET 0 -10 0", "CHANNELS 3 Zrotation Yrotation Xrotation"]
    text += ["End Site", "{", "OFFSET 0 -10 0", "}"] + ["}"] * len(names)
    count = len(frames.strip().split("\n"))
    text += ["MOTION", f"Frames: {count}", "Frame Time: 0.0333333", frames.strip()]
    return lines.join(text) + lines


def test_a_mixamo_skeleton_maps_with_its_namespace(tmp_path):
    names = ["Hips", "Spine", "Spine1", "Spine2", "Neck", "Head"]
    names += [f"{s}{part}" for s in ("Left", "Right") for part in ("Arm", "ForeArm", "Hand")]
    names += [f"{s}{part}" for s in ("Left", "Right") for part in ("UpLeg", "Leg", "Foot")]
    prefixed = [f"mixamorig:{n}" for n in names]
    frame = " ".join(["0"] * (6 + 3 * (len(names) - 1)))
    path = tmp_path / "mixamo.bvh"
    path.write_text(_tiny(prefixed, frame))
    mapped = map_joints(read_bvh(path))
    assert mapped.convention.startswith("Mixamo")
    assert prefixed[mapped.joints["spine"]] == "mixamorig:Spine1"
    assert prefixed[mapped.joints["left_knee"]] == "mixamorig:LeftLeg"


def test_an_unknown_skeleton_is_refused_with_one_sentence_listing_its_joints(tmp_path):
    path = tmp_path / "robot.bvh"
    path.write_text(_tiny(["Base", "Link1", "Link2"], "0 0 0 0 0 0 0 0 0 0 0 0"))
    with pytest.raises(UserError) as error:
        map_joints(read_bvh(path))
    message = str(error.value)
    assert "Base, Link1, Link2" in message and str(path) in message
    assert message.endswith(".") and message.count(". ") == 0


def test_crlf_and_root_rotations_past_180_degrees(tmp_path):
    """A CRLF file, and a root yawed 270 degrees: the same pose as -90."""
    frames = "1 2 3 0 270 0 0 0 30\n1 2 3 0 -90 0 0 0 30"
    path = tmp_path / "crlf.bvh"
    path.write_bytes(_tiny(["Hips", "Knee"], frames, "\r\n").encode())
    clip = read_bvh(path)
    assert clip.frame_count == 2 and clip.names == ["Hips", "Knee"]
    positions, rotations = clip.forward_kinematics()
    tip = clip.end_sites(positions, rotations)[1]
    assert positions[0] == pytest.approx(positions[1]) and tip[0] == pytest.approx(tip[1])
    # Below a root at (1, 2, 3) turned -90 degrees about Y (z goes to -x), the shin bent
    # 30 degrees about X (towards -z): the tip lies 10 sin 30 along +x.
    bend = math.radians(30)
    assert tip[0] == pytest.approx([1 + 10 * math.sin(bend), 2 - 10 - 10 * math.cos(bend), 3])


def test_broken_files_give_one_sentence(tmp_path):
    with pytest.raises(UserError, match="does not exist"):
        read_bvh(tmp_path / "missing.bvh")
    (tmp_path / "text.bvh").write_text("hello\n")
    with pytest.raises(UserError, match="not a BVH file"):
        read_bvh(tmp_path / "text.bvh")
    short = _tiny(["Hips", "Knee"], "0 0 0 0 0 0 0 0 0").replace("Frames: 1", "Frames: 5")
    (tmp_path / "short.bvh").write_text(short)
    with pytest.raises(UserError, match="holds 1 whole frames"):
        read_bvh(tmp_path / "short.bvh")


def test_cmu_units_give_a_figure_of_adult_size(mocap):
    """CMU's unit (1/0.45 inch) is found from the rest figure. At that scale each
    subject's thigh and shin (hip to ankle) make a stature of 1.6-1.9 m (they are
    0.530 - 0.039 of it, Winter), and the lowest point over the take lies on the floor
    (y = 0). The head is lower than that stature would put it: these files' torsos are
    short (see the folder's README)."""
    for path in sorted(mocap.glob("*.bvh")):
        clip = read_bvh(path)
        unit = metres_per_unit(clip)
        assert unit == pytest.approx(CMU_METRES_PER_UNIT)
        mapped = map_joints(clip).joints
        rest = clip.rest_positions() * unit
        legs = [
            np.linalg.norm(rest[mapped[f"{s}_knee"]] - rest[mapped[f"{s}_hip"]])
            + np.linalg.norm(rest[mapped[f"{s}_ankle"]] - rest[mapped[f"{s}_knee"]])
            for s in ("left", "right")
        ]
        assert 1.6 <= np.mean(legs) / (0.530 - 0.039) <= 1.9, path.name
        first = 1 if clip.starts_with_reference_pose() else 0
        positions, rotations = clip.forward_kinematics(slice(first, None))
        tips = np.concatenate(list(clip.end_sites(positions, rotations).values()))
        assert -0.08 <= tips[:, 1].min() * unit <= 0.05, path.name


def test_units_of_a_centimetre_file(tmp_path):
    names = ["Hips", "Chest", "Neck", "Head"]
    text = _tiny(names, " ".join(["0"] * 15)).replace("OFFSET 0 -10 0", "OFFSET 0 40 0")
    (tmp_path / "cm.bvh").write_text(text)
    assert metres_per_unit(read_bvh(tmp_path / "cm.bvh")) == 0.01
