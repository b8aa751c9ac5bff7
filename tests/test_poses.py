"""Pose files: the shipped reference poses, save/load round trip, lookup, consistency checks."""

from __future__ import annotations

from datetime import datetime, timedelta, timezone

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from projecttree import ROOT, shipped_arm
from seqrun.errors import SequenceInvalid, UserInputError
from seqrun.arm.poses import (
    NOTE_PREFIX,
    SCHEMA_COMMENT,
    PoseFile,
    available_poses,
    check_pose,
    find_pose,
    load_pose,
    pose_document,
    pose_yaml,
    save_pose,
)
from tiers import examples

POSES = ROOT / "poses"
ARM = shipped_arm()

REFERENCE_JOINTS = {  # shared/reference/lwa3-arm.md, user degrees
    "totem": [0, 0, 0, 0, 0, 0, 0],
    "park": [0, -90, 0, -120.32, 0, 115.74, 0],
    "opsafe": [70, 30, 0, 70, 20, 50, 0],
}


@pytest.mark.parametrize("name", sorted(REFERENCE_JOINTS))
def test_shipped_pose_loads_and_agrees_with_fk(name):
    pose = load_pose(find_pose(name, POSES))
    assert pose.name == name
    assert pose.arm == ARM.name
    assert pose.source == "reference"
    assert list(pose.joints_deg) == ARM.joint_names
    assert list(pose.joints_deg.values()) == REFERENCE_JOINTS[name]
    problems = [f for f in check_pose(pose, ARM) if not f.startswith(NOTE_PREFIX)]
    assert problems == []


@pytest.mark.parametrize("name", sorted(REFERENCE_JOINTS))
def test_shipped_pose_is_what_save_pose_writes(name):
    path = find_pose(name, POSES)
    pose = load_pose(path)
    regenerated = pose_document(pose.name, ARM, pose.joints_deg, pose.description, pose.source)
    assert path.read_text(encoding="utf-8") == pose_yaml(regenerated)
    assert path.read_text(encoding="utf-8").splitlines()[0] == SCHEMA_COMMENT


def test_shipped_end_effectors():
    stored = {name: load_pose(find_pose(name, POSES)).end_effector for name in REFERENCE_JOINTS}
    assert stored["totem"].position_mm == (-0.006, -0.1, 1083.0)
    assert stored["totem"].rpy_deg == (180.0, 0.0, 0.0)
    assert stored["park"].position_mm == (365.903, -0.1, 47.921)
    assert stored["park"].rpy_deg == (0.0, 85.42, 180.0)
    assert stored["opsafe"].position_mm == (-136.305, 510.761, 389.804)
    assert stored["opsafe"].rpy_deg == (-22.318, -27.505, 124.351)


def test_park_is_inside_the_limits_and_beyond_them_is_a_note():
    park = load_pose(find_pose("park", POSES))
    assert check_pose(park, ARM) == []  # j4's lower limit is Park's (arms/lwa3.yaml)
    beyond = park.model_copy(update={"joints_deg": {**park.joints_deg, "j4": -121.0}})
    assert f"{NOTE_PREFIX}j4 -121 deg is outside its limits [-120.32, 120]" in \
        check_pose(beyond, ARM)


def test_file_key_order_is_readable():
    text = (POSES / "opsafe.yaml").read_text(encoding="utf-8")
    keys = [line.split(":")[0] for line in text.splitlines()
            if line and not line.startswith((" ", "#"))]
    assert keys == ["name", "description", "arm", "source", "joints_deg", "end_effector"]
    assert "  position_mm: [-136.305, 510.761, 389.804]" in text.splitlines()


joint_values = st.floats(-180, 180, allow_nan=False).map(lambda v: round(v, 4))
# (no control characters: a seqrun file holds printable text, and loading refuses them at
# file:line:col since issue 43; tabs and line breaks are fine)
descriptions = st.text(st.characters(codec="utf-8", exclude_categories=("Cs", "Cc"),
                                     include_characters="\t\n"), max_size=150)


@settings(max_examples=examples(40), deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@example(joints=[0.0] * 6, description="next\u2028line", seconds=0, source=None)  # YAML line break
@example(joints=[0.0] * 6, description="yes", seconds=0, source=None)  # YAML 1.1 boolean
@given(joints=st.lists(joint_values, min_size=6, max_size=6), description=descriptions,
       seconds=st.integers(0, 10**9), source=st.sampled_from(["reference", "arm", "manual", None]))
def test_save_load_round_trip(tmp_path, joints, description, seconds, source):
    joints.insert(2, 0.0)  # j3 is locked at 0
    saved_at = datetime(2020, 1, 1, tzinfo=timezone.utc) + timedelta(seconds=seconds)
    pose = pose_document("probe", ARM, joints, description, source, saved_at=saved_at)
    path = tmp_path / "probe.yaml"
    save_pose(path, pose)
    assert load_pose(path) == pose
    assert [f for f in check_pose(pose, ARM) if not f.startswith(NOTE_PREFIX)] == []


def test_pose_document_fills_a_locked_joint_left_out():
    pose = pose_document("p", ARM, {"j1": 1, "j2": 2, "j4": 4, "j5": 5, "j6": 6, "j7": 7})
    assert pose.joints_deg == {"j1": 1, "j2": 2, "j3": 0, "j4": 4, "j5": 5, "j6": 6, "j7": 7}


def test_unknown_pose_lists_the_available_ones():
    with pytest.raises(UserInputError) as info:
        find_pose("nowhere", POSES)
    assert str(info.value) == f"unknown pose 'nowhere'; available poses: opsafe, park, totem (in {POSES})"


def test_unknown_pose_in_a_missing_directory(tmp_path):
    with pytest.raises(UserInputError, match="does not exist"):
        find_pose("totem", tmp_path / "absent")
    assert available_poses(tmp_path / "absent") == {}


def test_pose_names_are_file_names_only():
    with pytest.raises(UserInputError):
        find_pose("../arms/lwa3", POSES)


def test_extra_keys_are_refused(tmp_path):
    path = tmp_path / "typo.yaml"
    path.write_text((POSES / "totem.yaml").read_text() + "colour: red\n")
    with pytest.raises(SequenceInvalid):
        load_pose(path)


def _edited(pose: PoseFile, **changes) -> PoseFile:
    return pose.model_copy(update=changes)


def test_check_pose_finds_every_problem():
    totem = load_pose(POSES / "totem.yaml")
    moved = totem.end_effector.model_copy(update={"position_mm": (-0.006, -0.1, 1082.0)})
    assert check_pose(_edited(totem, end_effector=moved), ARM) == [
        "end_effector.position_mm [-0.006, -0.100, 1082.000] is 1.000 mm from forward "
        "kinematics [-0.006, -0.100, 1083.000]"]
    turned = totem.end_effector.model_copy(update={"rpy_deg": (180.0, 0.2, 0.0)})
    assert check_pose(_edited(totem, end_effector=turned), ARM) == [
        "end_effector.rpy_deg [180.000, 0.200, 0.000] is 0.200 deg from forward kinematics "
        "[180.000, 0.000, 0.000]"]
    # within tolerance: 0.4 mm, 0.09 deg
    close = totem.end_effector.model_copy(
        update={"position_mm": (-0.006, 0.3, 1083.0), "rpy_deg": (180.0, 0.0, 0.09)})
    assert check_pose(_edited(totem, end_effector=close), ARM) == []

    locked = dict(totem.joints_deg, j3=5.0)
    assert check_pose(_edited(totem, joints_deg=locked), ARM) == [
        "j3 is locked at 0 deg, the pose has 5"]

    odd = {k: v for k, v in totem.joints_deg.items() if k != "j7"} | {"j8": 0.0}
    assert check_pose(_edited(totem, joints_deg=odd), ARM) == [
        "unknown joint(s) j8; the arm has j1, j2, j3, j4, j5, j6, j7",
        "missing joint(s) j7"]

    assert check_pose(_edited(totem, arm="another arm"), ARM) == [
        f"made for arm 'another arm', not '{ARM.name}'"]


def test_rpy_is_compared_as_rotation_at_the_singularity():
    # j2 = -90 points the tool sideways: pitch is exactly 90 deg, where only roll - yaw
    # matters; (-150, 90, 30) is the same rotation as (180, 90, 0), written differently.
    pose = pose_document("sideways", ARM, [0, -90, 0, 0, 0, 0, 0])
    assert pose.end_effector.rpy_deg == (180.0, 90.0, 0.0)
    same = pose.end_effector.model_copy(update={"rpy_deg": (-150.0, 90.0, 30.0)})
    assert check_pose(_edited(pose, end_effector=same), ARM) == []
    other = pose.end_effector.model_copy(update={"rpy_deg": (-150.0, 90.0, 0.0)})
    assert check_pose(_edited(pose, end_effector=other), ARM) == [
        "end_effector.rpy_deg [-150.000, 90.000, 0.000] is 30.000 deg from forward kinematics "
        "[180.000, 90.000, 0.000]"]
