"""``seqrun urdf`` (seqrun/arm/urdf.py): the URDF's forward kinematics is seqrun's.

The URDF is read back by a reader written here from the URDF specification alone
(xml.etree and numpy: a joint's ``origin`` is ``xyz`` then ``rpy`` as fixed-axis X-Y-Z
rotations, a revolute joint turns its child about ``axis`` by the joint's angle, lengths in
metres), not by seqrun's code, and its link frames are compared with seqrun's frames
(seqrun.arm.kinematics) for random joint angles, to 1e-6 mm. The shapes are checked the same
way against seqrun's link and tool volumes (seqrun.arm.geometry).
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from projecttree import ROOT
from seqrun.arm.description import ArmDescription, load_arm
from seqrun.arm.geometry import Geometry
from seqrun.arm.kinematics import Chain, frame_matrix, frame_transforms
from seqrun.arm.urdf import urdf

ARM_FILE = ROOT / "arms" / "lwa3.yaml"
TOLERANCE_MM = 1e-6


# ---------------------------------------------------------------- an independent reader
def _rotation_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _rotation_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rotation_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _origin(element: ET.Element | None) -> np.ndarray:
    """URDF ``<origin xyz rpy>``: roll about x, then pitch about y, then yaw about z, all
    about the parent's fixed axes; missing means zero."""
    frame = np.eye(4)
    if element is None:
        return frame
    x, y, z = (float(v) for v in element.get("xyz", "0 0 0").split())
    roll, pitch, yaw = (float(v) for v in element.get("rpy", "0 0 0").split())
    frame[:3, :3] = _rotation_z(yaw) @ _rotation_y(pitch) @ _rotation_x(roll)
    frame[:3, 3] = (x, y, z)
    return frame


def _about_axis(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues' formula: ``angle`` about the unit ``axis``."""
    k = axis / np.linalg.norm(axis)
    skew = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    frame = np.eye(4)
    frame[:3, :3] = np.eye(3) + math.sin(angle) * skew + (1 - math.cos(angle)) * skew @ skew
    return frame


@dataclass
class Joint:
    name: str
    kind: str
    parent: str
    origin: np.ndarray
    axis: np.ndarray
    limit: dict


class Urdf:
    def __init__(self, text: str) -> None:
        self.root = ET.fromstring(text)
        assert self.root.tag == "robot"
        self.links = {link.get("name"): link for link in self.root.findall("link")}
        self.joints: dict[str, Joint] = {}  # by child link
        for joint in self.root.findall("joint"):
            child = joint.find("child").get("link")
            assert child not in self.joints, f"{child} has two parents"
            axis = joint.find("axis")
            limit = joint.find("limit")
            self.joints[child] = Joint(
                joint.get("name"), joint.get("type"), joint.find("parent").get("link"),
                _origin(joint.find("origin")),
                np.array([float(v) for v in (axis.get("xyz") if axis is not None
                                             else "1 0 0").split()]),
                dict(limit.attrib) if limit is not None else {})
        roots = [name for name in self.links if name not in self.joints]
        assert len(roots) == 1, roots
        self.root_link = roots[0]

    def movable(self) -> dict[str, Joint]:
        return {j.name: j for j in self.joints.values() if j.kind != "fixed"}

    def link_frames(self, angles: dict[str, float]) -> dict[str, np.ndarray]:
        """Every link's frame in the root's, metres, at ``angles`` (joint name -> rad)."""
        frames = {self.root_link: np.eye(4)}

        def frame(link: str) -> np.ndarray:
            if link not in frames:
                joint = self.joints[link]
                motion = np.eye(4)
                if joint.kind in ("revolute", "continuous"):
                    motion = _about_axis(joint.axis, angles[joint.name])
                else:
                    assert joint.kind == "fixed", joint.kind
                frames[link] = frame(joint.parent) @ joint.origin @ motion
            return frames[link]

        for link in self.links:
            frame(link)
        return frames

    def shapes(self, kind: str) -> dict[str, dict[str, list]]:
        """``<visual>``/``<collision>`` elements: link -> element name -> [(origin, geometry)]."""
        out: dict[str, dict[str, list]] = {}
        for name, link in self.links.items():
            for element in link.findall(kind):
                geometry = element.find("geometry")[0]
                out.setdefault(name, {}).setdefault(element.get("name"), []).append(
                    (_origin(element.find("origin")), geometry.tag, dict(geometry.attrib)))
        return out


# ---------------------------------------------------------------- arms
def shipped() -> ArmDescription:
    return load_arm(ARM_FILE)


def with_tools_and_j3_at(locked_deg: float) -> ArmDescription:
    """The shipped arm with j3 locked elsewhere and three kinds of tool."""
    data = shipped().model_dump(mode="json")
    data["joints"][2]["locked"] = locked_deg
    data["tools"] = [
        {"name": "probe", "xyz_mm": [0, 0, -120], "rpy_deg": [180, 0, 30],
         "capsules": [{"name": "shaft", "end_mm": [0, 0, -100], "radius_mm": 15},
                      {"name": "tip", "start_mm": [0, 0, -100], "end_mm": [5, 3, -120],
                       "radius_mm": 6}]},
        {"name": "pointer", "xyz_mm": [20, -10, -60], "rpy_deg": [10, -20, 35]},
        {"name": "camera", "xyz_mm": [0, 40, -80], "capsules": []},
    ]
    data["default_tool"] = "probe"
    return ArmDescription.model_validate(data)


ARMS = {"shipped": shipped(), "tools, j3 at 25": with_tools_and_j3_at(25.0),
        "tools, j3 at -90": with_tools_and_j3_at(-90.0)}


def random_angles(arm: ArmDescription):
    """Joint angles (deg) within the limits, locked joints at their value."""
    return st.tuples(*[st.just(float(j.locked)) if j.locked is not None
                       else st.floats(*j.limits_deg, allow_nan=False) for j in arm.joints])


def frames_mm(model: Urdf, arm: ArmDescription, degrees) -> dict[str, np.ndarray]:
    angles = {j.name: math.radians(d) for j, d in zip(arm.joints, degrees)}
    frames = model.link_frames({name: angles[name] for name in model.movable()})
    for frame in frames.values():
        frame[:3, 3] *= 1000.0
    return frames


def seqrun_frames(arm: ArmDescription, degrees, prefix: str) -> dict[str, np.ndarray]:
    chain = Chain.from_arm(arm)
    frames = frame_transforms(chain, np.radians(degrees))
    names = [f"{prefix}{j.name}" for j in arm.joints] + [f"{prefix}end_effector"]
    out = dict(zip(names, frames))
    out[f"{prefix}base"] = np.eye(4)
    for tool in arm.tools:
        out[f"{prefix}tool_{tool.name}"] = frames[-1] @ frame_matrix(tool)
    return out


def assert_same_frames(ours: dict, theirs: dict) -> None:
    assert sorted(ours) == sorted(theirs)
    for name in ours:
        assert np.max(np.abs(ours[name][:3, 3] - theirs[name][:3, 3])) < TOLERANCE_MM, name
        assert np.max(np.abs(ours[name][:3, :3] - theirs[name][:3, :3])) < 1e-12, name


# ---------------------------------------------------------------- the tests
@pytest.mark.parametrize("label", list(ARMS))
@settings(max_examples=150, deadline=None)
@given(data=st.data())
def test_the_urdf_forward_kinematics_is_seqruns(label, data):
    arm = ARMS[label]
    model = Urdf(urdf(arm, "lwa3/"))
    degrees = data.draw(random_angles(arm))
    assert_same_frames(frames_mm(model, arm, degrees), seqrun_frames(arm, degrees, "lwa3/"))


def test_joints_limits_and_the_locked_joint():
    arm = shipped()
    model = Urdf(urdf(arm, "lwa3/"))
    movable = model.movable()
    assert list(movable) == ["j1", "j2", "j4", "j5", "j6", "j7"]  # joint_states' names
    for name, joint in movable.items():
        spec = arm.joint(name)
        assert joint.kind == "revolute"
        assert list(joint.axis) == [0.0, 0.0, 1.0]
        assert float(joint.limit["lower"]) == math.radians(spec.limits_deg[0])
        assert float(joint.limit["upper"]) == math.radians(spec.limits_deg[1])
        assert float(joint.limit["velocity"]) == math.radians(spec.max_velocity_deg_s)
        assert "effort" in joint.limit  # required by the URDF specification
    locked = model.joints["lwa3/j3"]
    assert (locked.name, locked.kind, locked.parent) == ("j3", "fixed", "lwa3/j2")
    assert model.root.get("name") == "lwa3"


def _segment_of(origin_and_geometry: list, link_frame: np.ndarray) -> tuple:
    """A capsule drawn as cylinder + two spheres: its two ends (mm, base frame), radius."""
    cylinders = [(o, g) for o, tag, g in origin_and_geometry if tag == "cylinder"]
    spheres = [(o, g) for o, tag, g in origin_and_geometry if tag == "sphere"]
    assert len(cylinders) == 1 and len(spheres) == 2
    (origin, cylinder), = cylinders
    half = float(cylinder["length"]) / 2
    ends = [link_frame @ origin @ np.array([0, 0, z, 1.0]) for z in (-half, half)]
    centres = [link_frame @ o[:, 3] for o, _ in spheres]
    for end, centre in zip(ends, centres):  # the spheres close the cylinder's ends
        assert np.max(np.abs(end - centre)) * 1000 < TOLERANCE_MM
    radii = {float(cylinder["radius"])} | {float(g["radius"]) for _, g in spheres}
    assert len(radii) == 1
    return centres[0][:3] * 1000, centres[1][:3] * 1000, radii.pop() * 1000


@pytest.mark.parametrize("label", list(ARMS))
@settings(max_examples=40, deadline=None)
@given(data=st.data())
def test_visuals_and_collisions_are_seqruns_volumes(label, data):
    """Each of seqrun's capsules (links and tools) is a cylinder between two spheres, in the
    link that carries it; a capsule that bends with a joint between its ends (the forearm)
    is drawn in pieces through the joint origins, from its start to its end."""
    arm = ARMS[label]
    text = urdf(arm, "lwa3/")
    model = Urdf(text)
    degrees = data.draw(random_angles(arm))
    frames = model.link_frames({j: math.radians(d) for j, d in
                                zip(arm.joint_names, degrees) if j in model.movable()})
    geometry = Geometry(arm)
    expected = geometry.endpoints(np.radians(degrees))
    names = geometry.capsule_names + [part.label for part in geometry.tools.parts]
    radii = [c.radius_mm for c in arm.geometry.capsules] + \
        [part.radius_mm for part in geometry.tools.parts]
    visuals, collisions = model.shapes("visual"), model.shapes("collision")
    for name, (start, end), radius in zip(names, expected, radii):
        pieces = sorted({(piece, link) for link, elements in visuals.items()
                         for piece in (e.rsplit(" ", 1)[0] for e in elements)
                         if re.fullmatch(re.escape(name) + r"( \d+/\d+)?", piece)})
        assert pieces, f"{name} is not in the URDF"
        drawn = []
        for piece, link in pieces:
            drawn.append(_segment_of(visuals[link][f"{piece} cylinder"]
                                     + visuals[link][f"{piece} sphere"], frames[link]))
            if radius > 0:
                in_collision = _segment_of(collisions[link][f"{piece} cylinder"]
                                           + collisions[link][f"{piece} sphere"], frames[link])
                assert all(np.array_equal(a, b) for a, b in zip(in_collision, drawn[-1]))
            else:  # a tip line: drawn, no body to collide
                assert f"{piece} cylinder" not in collisions.get(link, {})
        assert np.max(np.abs(drawn[0][0] - start)) < TOLERANCE_MM, name
        assert np.max(np.abs(drawn[-1][1] - end)) < TOLERANCE_MM, name
        for before, after in zip(drawn, drawn[1:]):  # the pieces join
            assert np.max(np.abs(before[1] - after[0])) < TOLERANCE_MM, name
        for _, _, drawn_radius in drawn:
            assert drawn_radius == pytest.approx(radius if radius > 0 else 1.0, abs=1e-9)


def test_the_forearm_is_drawn_in_two_pieces_and_the_others_in_one():
    """j4 to j6 bends with j5 (j5's axis misses j4's origin): no one link carries it."""
    visuals = Urdf(urdf(shipped(), "lwa3/")).shapes("visual")
    pieces = {element.rsplit(" ", 1)[0]: link for link, elements in visuals.items()
              for element in elements}
    assert pieces == {"column": "lwa3/j1", "upper_arm": "lwa3/j2", "forearm 1/2": "lwa3/j4",
                      "forearm 2/2": "lwa3/j5", "wrist": "lwa3/j6", "hand": "lwa3/j7"}


runner = CliRunner()


def test_seqrun_urdf_writes_the_file_and_prints_it(tmp_path):
    import seqrun.cli.urdf  # noqa: F401  (registers `urdf`)
    from seqrun.cli.app import app

    target = tmp_path / "lwa3.urdf"
    written = runner.invoke(app, ["urdf", "--arm", str(ARM_FILE), "-o", str(target)])
    assert written.exit_code == 0, written.output
    assert target.read_text(encoding="utf-8") == urdf(shipped(), "lwa3/")
    assert written.stdout == ""
    printed = runner.invoke(app, ["urdf", "--arm", str(ARM_FILE), "--arm-name", "left arm"])
    assert printed.exit_code == 0, printed.output
    assert printed.stdout == urdf(shipped(), "left_arm/")
    missing = runner.invoke(app, ["urdf", "--arm", str(tmp_path / "none.yaml")])
    assert missing.exit_code == 2 and missing.stderr.startswith("error: arm file ")


def test_one_arm_of_several_is_named_by_its_id(tmp_path, monkeypatch):
    """In a campaign with several arms, --arm-id B: B's arm file, links B/base ... (the
    frames `seqrun ros --arm-id B` publishes)."""
    import shutil

    import seqrun.cli.urdf  # noqa: F401  (registers `urdf`)
    from seqrun.cli.app import app

    campaign = tmp_path / "two-arms"
    shutil.copytree(ROOT / "examples" / "two-arms", campaign)
    monkeypatch.chdir(campaign)
    monkeypatch.setenv("SEQRUN_STATE_DIR", str(tmp_path / "state"))
    result = runner.invoke(app, ["urdf", "--arm-id", "B"])
    assert result.exit_code == 0, result.output
    model = Urdf(result.stdout)
    assert model.root.get("name") == "B" and model.root_link == "B/base"
    unknown = runner.invoke(app, ["urdf", "--arm-id", "C"])
    assert unknown.exit_code == 2 and "C" in unknown.stderr


def test_the_fixed_frames_for_tf_static_are_the_chains_own():
    """What /tf_static carries (the URDF's fixed joints) is what /tf carried for those
    frames: the locked j3 in j2, the end-effector on the flange, each tool's TCP."""
    from seqrun.service.kinematics import fixed_transforms, link_transforms

    arm = ARMS["tools, j3 at 25"]
    fixed = {child: (parent, xyz, q) for parent, child, xyz, q in
             fixed_transforms(arm, "lwa3/")}
    assert sorted(fixed) == ["lwa3/end_effector", "lwa3/j3", "lwa3/tool_camera",
                             "lwa3/tool_pointer", "lwa3/tool_probe"]
    degrees = [10, -30, 25, 40, -50, 60, -70]
    moving = {child: (parent, xyz, q) for parent, child, xyz, q in
              link_transforms(arm, degrees, "lwa3/")}
    for child in ("lwa3/j3", "lwa3/end_effector"):
        parent, xyz, q = fixed[child]
        assert parent == moving[child][0]
        assert np.allclose(xyz, moving[child][1], atol=1e-12)
        assert np.allclose(q, moving[child][2], atol=1e-12) or \
            np.allclose(q, -np.array(moving[child][2]), atol=1e-12)
    parent, xyz, _ = fixed["lwa3/tool_probe"]
    assert parent == "lwa3/end_effector" and np.allclose(xyz, (0, 0, -0.12))
