"""Tools are geometry (issue 23.3): a tool's volume is checked against the workspace guards,
the obstacles and the links on every planned path and every control cycle, as the links are.

The reproduction: with a 400 mm tool on the flange, a move to a tool pose 58 mm below the
desk validated and PASSED, because only the links were checked.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from pydantic import ValidationError

from projecttree import ROOT, make_project, shipped_arm, write_sequence
from seqrun.arm.cartesian import solver_for, tool_pose
from seqrun.arm.description import ArmDescription, load_arm
from seqrun.arm.geometry import Geometry
from seqrun.arm.kinematics import Chain, frame_origins
from seqrun.sequence.loader import load_sequence
from seqrun.sequence.validation import validate_sequence
from seqrun.service.dryrun import dry_run
from tiers import examples

PARK = {"j1": 0, "j2": -90, "j3": 0, "j4": -120.32, "j5": 0, "j6": 115.74, "j7": 0}
UP = "- reset\n- home\n- set_limits\n- move: totem\n- move: opsafe\n"  # lines 4-8
#: The commented example of arms/lwa3.yaml, replaced by a test's own tools.
TOOLS_EXAMPLE = "# tools:\n#   - {name: probe"
#: Pointing down (the end-effector's z up: the tool along its -z), the tip 58 mm below the desk.
INTO_THE_DESK = "- move: {position_mm: [0, 400, -58], rpy_deg: [0, 0, 0]}\n"  # line 9


def tool_project(root: Path, tools: str) -> Path:
    """A campaign whose arm file carries ``tools`` (YAML lines at the top level)."""
    project = make_project(root, arm_changes={TOOLS_EXAMPLE: tools + "\n" + TOOLS_EXAMPLE})
    return project


PROBE = "tools:\n  - {name: probe, xyz_mm: [0, 0, -400]}\ndefault_tool: probe\n"


@pytest.fixture
def probe(tmp_path) -> tuple[Path, ArmDescription]:
    project = tool_project(tmp_path / "p", PROBE)
    return project, load_arm(project / "arms" / "lwa3.yaml")


def check(project: Path, arm: ArmDescription, steps: str):
    return validate_sequence(load_sequence(write_sequence(project, steps)), arm, PARK)


def messages(result) -> list[str]:
    return [f"{Path(e.file).name}:{e.line}:{e.column}: {e.message}" for e in result.errors]


# --------------------------------------------------------------------------- validation
def test_a_move_that_takes_the_tool_tip_into_the_desk_is_refused_at_its_line(probe):
    project, arm = probe
    result = check(project, arm, UP + INTO_THE_DESK)
    found = messages(result)
    assert len(found) == 2, found
    assert found[0].startswith("s.yaml:9:3: this move takes the tool probe into the desk (at ")
    assert found[1].startswith("s.yaml:9:3: this move takes the tool probe down to z = -58.")
    assert found[1].endswith("below the 'desk' guard at 10 mm")
    assert result.clearances[6].point == "tool probe"
    assert result.proximities[6].pair == "tool probe~desk"


def test_a_straight_line_into_the_desk_is_refused_at_its_line(probe):
    project, arm = probe
    steps = (UP + "- move: {position_mm: [0, 400, 100], rpy_deg: [0, 0, 0]}\n"
             "- move_linear: {position_mm: [0, 0, -158], relative: true, speed_mm_s: 20}\n")
    found = messages(check(project, arm, steps))
    assert [m.split(" (at ")[0] for m in found] == [
        "s.yaml:10:3: this move takes the tool probe into the desk",
        "s.yaml:10:3: this move takes the tool probe down to z = -57.999 mm"]
    assert all("straight line of the tool" in m for m in found)


def test_the_same_target_clear_of_the_desk_passes(probe):
    project, arm = probe
    result = check(project, arm, UP + "- move: {position_mm: [0, 400, 100], "
                                      "rpy_deg: [0, 0, 0]}\n")
    assert result.errors == []
    assert result.clearances[6].point == "tool probe"
    assert 10 < result.clearances[6].z_mm < 100.5  # the joint-space plan dips on its way


def test_a_joint_move_is_checked_for_the_tool_too(probe):
    """The tool is on the flange whatever a step names: a move to joint angles that puts the
    probe through the desk is refused like a move to a tool pose."""
    project, arm = probe
    found = messages(check(project, arm, UP + "- move: {joints: {j1: 90, j2: 24.377, "
                                              "j4: 82.182, j5: 0, j6: 73.441, j7: -90}}\n"))
    assert any("tool probe down to z = -5" in m for m in found), found


def test_a_tools_capsules_are_its_volume(tmp_path):
    """A fat tool (radius 60 mm) whose tip line stays 40 mm above the desk still reaches
    into it; the tip line alone would not. (Such a tool cannot stand in Park either: the
    moves from there are refused too, so only the last move's findings are compared.)"""
    steps = UP + "- move: {position_mm: [0, 400, 40], rpy_deg: [0, 0, 0]}\n"
    line = tool_project(tmp_path / "line", PROBE)
    assert check(line, load_arm(line / "arms" / "lwa3.yaml"), steps).errors == []
    fat = tool_project(tmp_path / "fat", "tools:\n  - {name: probe, xyz_mm: [0, 0, -400], "
                                         "capsules: [{end_mm: [0, 0, -400], radius_mm: 60}]}\n"
                                         "default_tool: probe\n")
    found = messages(check(fat, load_arm(fat / "arms" / "lwa3.yaml"), steps))
    last = [m.split(" (at ")[0] for m in found if m.startswith("s.yaml:9:")]
    assert last[0] == "s.yaml:9:3: this move takes the tool probe into the desk"
    prefix = "s.yaml:9:3: this move takes the tool probe down to z = "
    assert last[1].startswith(prefix)  # 60 mm below the tip line, which dips below 40 mm
    assert float(last[1].removeprefix(prefix).removesuffix(" mm")) < -20


def test_a_tool_without_a_body_is_not_checked(tmp_path):
    """capsules: [] says the TCP is a point in the air (a camera's focus): nothing to hit."""
    project = tool_project(tmp_path / "p", "tools:\n  - {name: focus, xyz_mm: [0, 0, -400], "
                                           "capsules: []}\ndefault_tool: focus\n")
    result = check(project, load_arm(project / "arms" / "lwa3.yaml"), UP + INTO_THE_DESK)
    assert result.errors == []


# --------------------------------------------------------------------------- run time
def test_the_run_halts_the_tool_at_the_guard(probe, monkeypatch):
    """With validation's path checks switched off, the executor streams the move and its
    run-time guard check halts it when the probe's tip crosses the guard."""
    from seqrun.sequence import validation

    project, arm = probe
    monkeypatch.setattr(validation.Checker, "check_path_guards", lambda *a, **k: None)
    run = dry_run(load_sequence(write_sequence(project, UP + INTO_THE_DESK)), arm, PARK)
    assert run.result.exit_code == 3
    assert run.result.fault["cause"] == "workspace_guard"
    assert "workspace guard 'desk': tool probe at z = 9." in run.result.message
    assert run.result.min_heights_mm["desk:tool"] == pytest.approx(9.5, abs=0.6)


def test_without_guards_the_run_halts_the_tool_at_the_desk_obstacle(probe, monkeypatch):
    from seqrun.sequence import validation

    project, arm = probe
    arm = arm.model_copy(update={"workspace": arm.workspace.model_copy(update={"guards": []})})
    monkeypatch.setattr(validation.Checker, "check_path_guards", lambda *a, **k: None)
    run = dry_run(load_sequence(write_sequence(project, UP + INTO_THE_DESK)), arm, PARK)
    assert run.result.exit_code == 3
    assert run.result.fault["cause"] == "collision"
    assert "geometry: tool probe 4." in run.result.message and "from desk" in run.result.message


# --------------------------------------------------------------------------- the geometry
FAT = {"name": "probe", "xyz_mm": [0, 0, -250],
       "capsules": [{"end_mm": [0, 0, -250], "radius_mm": 25}]}


def arm_with(*tools: dict) -> ArmDescription:
    return ArmDescription.model_validate({**shipped_arm().model_dump(), "tools": list(tools)})


@settings(max_examples=examples(100), deadline=None)
@given(q=arrays(np.float64, 7, elements=st.floats(-3.2, 3.2)))
def test_the_tools_points_are_where_the_tool_frame_puts_them(q):
    """The tip line ends at the TCP of inverse kinematics' tool chain, for any joints."""
    arm = arm_with({"name": "probe", "xyz_mm": [10, -20, -300], "rpy_deg": [30, 0, 90]})
    q = q.copy()
    q[2] = 0.0  # j3 is locked
    origins = frame_origins(Chain.from_arm(arm), q, Geometry(arm).ee_points)
    tip = tool_pose(solver_for(arm, "probe"), np.degrees(q))[:3, 3]
    assert origins[-1] == pytest.approx(tip, abs=1e-9)
    assert origins[-2] == pytest.approx(origins[7], abs=1e-12)  # the line starts at the EE


@settings(max_examples=examples(100), deadline=None)
@given(q=arrays(np.float64, 7, elements=st.floats(-3.2, 3.2)))
def test_single_configuration_path_equals_the_batched_one_with_a_tool(q):
    geometry = Geometry(arm_with(FAT, {"name": "line", "xyz_mm": [0, 80, -100]}))
    values, names = geometry.clearances(q[None])
    fast = geometry.smallest(q)
    k = int(np.argmin(values[0]))
    assert fast.distance_mm == pytest.approx(values[0, k], abs=1e-9)


def test_a_tool_is_checked_against_the_links_it_is_not_bolted_to():
    geometry = Geometry(arm_with(FAT))
    tool_pairs = sorted(n for n in geometry._names if "tool" in n and "desk" not in n)
    assert tool_pairs == ["column~tool probe", "forearm~tool probe", "upper_arm~tool probe"]
    folded = geometry.smallest(np.radians([0, 30, 0, 100, 0, 110, 0]))
    assert folded.pair == "column~tool probe" and folded.distance_mm < -50
    assert geometry.smallest(np.radians([70, 30, 0, 70, 20, 50, 0])).distance_mm > 50


def test_allowed_pairs_and_ignore_links_may_name_a_tool():
    data = arm_with(FAT).model_dump()
    data["geometry"]["allowed_pairs"] = [["column", "probe"]]
    data["geometry"]["obstacles"][0]["ignore_links"] = ["column", "probe"]
    geometry = Geometry(ArmDescription.model_validate(data))
    assert not any(n in geometry._names for n in ("column~tool probe", "tool probe~desk"))
    assert "upper_arm~tool probe" in geometry._names


@pytest.mark.parametrize("tools, message", [
    ([{"name": "hand", "xyz_mm": [0, 0, -100]}], "duplicate capsule/obstacle/tool name(s): hand"),
    ([{"name": "probe", "xyz_mm": [0, 0, -100], "capsules": [
        {"end_mm": [0, 0, -50], "radius_mm": 10}, {"end_mm": [0, 0, -100], "radius_mm": 5}]}],
     "tool probe: a tool of several capsules names each one, differently"),
    ([{"name": "probe", "xyz_mm": [0, 0, -100], "capsules": [
        {"end_mm": [0, 0, -100], "radius_mm": 0}]}], "greater than 0"),
])
def test_the_arm_file_refuses_a_malformed_tool(tools, message):
    with pytest.raises(ValidationError, match=message.replace("(", r"\(").replace(")", r"\)")):
        arm_with(*tools)


def test_the_arm_files_commented_tool_example_is_a_valid_tool(tmp_path):
    text = (ROOT / "arms" / "lwa3.yaml").read_text(encoding="utf-8")
    start = text.index("# tools:\n")
    end = text.index("# default_tool: probe\n") + len("# default_tool: probe\n")
    example = "".join(line[2:] + "\n" for line in text[start:end].splitlines())
    path = tmp_path / "arm.yaml"
    path.write_text(text[:start] + example + text[end:], encoding="utf-8")
    arm = load_arm(path)
    assert arm.default_tool == "probe" and arm.tools[0].capsules[0].radius_mm == 15
    assert Geometry(arm).smallest(np.radians([70, 30, 0, 70, 20, 50, 0])).distance_mm > 50


def test_a_jog_ends_short_of_the_guard_for_the_tool(probe):
    """A jog is planned to end a margin above the guards; the tool's tip counts as the
    end-effector does (else the run-time check would halt the jog with a fault)."""
    from seqrun.service.jog import plan_jog

    _, arm = probe
    above_the_spot = np.array([90.014, 24.475, 0, 48.83, 0, 106.695, -89.986])  # tip 100 mm
    with_tool = plan_jog(arm, "j2", 0.5, above_the_spot, 10.0)
    bare = plan_jog(shipped_arm(), "j2", 0.5, above_the_spot, 10.0)
    assert with_tool.why_end == bare.why_end == "workspace guard 'desk'"
    assert with_tool.end_deg < 40 < 80 < bare.end_deg


@settings(max_examples=examples(100), deadline=None)
@given(q=arrays(np.float64, 7, elements=st.floats(-3.2, 3.2)),
       tip=st.tuples(*[st.floats(-300, 300)] * 3), radius=st.floats(1, 80))
def test_the_run_time_lowest_tool_point_is_the_validations(q, tip, radius):
    """The run's per-cycle guard height of the tools (plain floats) and the validation's
    (batched) agree, for any tool and any joints."""
    from seqrun.arm.kinematics import heights_of_points
    from seqrun.arm.tools import ToolVolumes

    arm = arm_with({"name": "t", "xyz_mm": list(tip),
                    "capsules": [{"start_mm": [0, 0, -10], "end_mm": list(tip),
                                  "radius_mm": radius}]},
                   {"name": "line", "xyz_mm": [0, 50, -100]})
    tools = ToolVolumes(arm)
    chain = Chain.from_arm(arm)
    _, tool_z = heights_of_points(chain, q, tools.points_mm)
    run_time, label = tools.lowest_z(tool_z)
    origins = frame_origins(chain, q[None], tools.points_mm)
    lowest, part = tools.lowest(origins[:, 8:, :])
    assert run_time == pytest.approx(float(lowest[0, 2]), abs=1e-9)
    assert label == tools.parts[int(part[0])].label or run_time == pytest.approx(
        float(np.min(origins[0, 8:, 2] - tools.point_radii)), abs=1e-9)
