"""The gripper (a PowerCube PG 70 module in the arm file): grip, release, check_gripper.

Validation refuses a grip force above the module's limit, widths beyond its stroke and
gripper steps on an arm without one; the dry run closes the simulated jaws on the part the
grip names; without a part the jaws close fully and the grip is a fault (Halt, exit 3); the
driver alone converts mm to the module's metres and N to its current limit.
"""

from __future__ import annotations

import struct
from pathlib import Path

import pytest

from projecttree import ARM_FILE, make_project, shipped_arm, write_sequence
from seqrun.arm.description import load_arm
from seqrun.arm.gripper import GripperSpec
from seqrun.errors import SequenceInvalid
from seqrun.service.dryrun import dry_run
from seqrun.service.runlog import read_trace
from seqrun.sequence.loader import load_sequence
from seqrun.sequence.validation import validate_sequence
from simrun import run_on_sim

ARM = shipped_arm()
PARK = {"j1": 0, "j2": -90, "j3": 0, "j4": -120.32, "j5": 0, "j6": 115.74, "j7": 0}
UP = "- reset\n- home\n- set_limits\n"  # lines 4-6: the gripper step is on line 7
GRIP = ("- release: {width_mm: 60}\n"
        "- grip: {part_width_mm: 40, force_n: 100}\n"
        "- check_gripper: {holding: true, width_mm: 40}\n"
        "- release: {width_mm: 60}\n"
        "- check_gripper: {holding: false, width_mm: 60}\n")


def findings(project: Path, steps: str) -> list[str]:
    result = validate_sequence(load_sequence(write_sequence(project, UP + steps)), ARM, PARK)
    return [f"{e.line}:{e.column}: {e.message}" for e in result.errors]


# --------------------------------------------------------------------------- validation
def test_a_grip_force_above_the_modules_limit_is_refused_at_the_force(project):
    [error] = findings(project, "- grip: {part_width_mm: 40, force_n: 250}\n")
    assert error == "7:38: force_n 250 N is above the gripper's limit 200 N " \
                    "(gripper.max_force_n)"


def test_widths_beyond_the_stroke_are_refused(project):
    errors = findings(project, "- release: {width_mm: 80}\n"
                               "- grip: {part_width_mm: 75, force_n: 50}\n")
    assert errors[0].startswith("7:23: width_mm 80 mm is beyond the gripper's stroke 70 mm")
    assert errors[1].startswith("8:25: part_width_mm 75 mm is beyond")


def test_gripper_steps_on_an_arm_without_a_gripper_are_refused(tmp_path):
    text = ARM_FILE.read_text(encoding="utf-8")
    section = text[text.index("\n# The gripper for capture"):]
    root = make_project(tmp_path / "p", arm_changes={section: "\n"})
    arm = load_arm(root / "arms" / "lwa3.yaml")
    assert arm.gripper is None  # optional: the arm file is valid without it
    result = validate_sequence(load_sequence(write_sequence(root, UP + GRIP)), arm, PARK)
    assert len(result.errors) == 5
    assert "grip: the arm file has no gripper" in result.errors[1].message


def test_a_check_gripper_needs_something_to_check(project):
    with pytest.raises(Exception, match="check_gripper needs 'holding', 'width_mm' or both"):
        load_sequence(write_sequence(project, UP + "- check_gripper: {tolerance_mm: 1}\n"))


def test_the_arm_file_refuses_a_bad_gripper():
    rows = {"module": 8, "stroke_mm": 70, "max_force_n": 200}
    with pytest.raises(ValueError, match="below max_force_n"):
        GripperSpec(**rows, force_current=[(0, 0.5), (100, 1.5)])
    with pytest.raises(ValueError, match="increase row by row"):
        GripperSpec(**rows, force_current=[(0, 1.5), (200, 0.5)])
    spec = GripperSpec(**rows, force_current=[(30, 0.5), (100, 1.5), (200, 3.0)])
    assert spec.current_for(100) == pytest.approx(1.5)
    assert spec.current_for(150) == pytest.approx(2.25)


def test_a_gripper_on_a_joints_module_id_is_refused(tmp_path):
    root = make_project(tmp_path / "p", arm_changes={"  module: 8\n": "  module: 7\n"})
    with pytest.raises(SequenceInvalid, match="gripper.module 7 is a joint's module id"):
        load_arm(root / "arms" / "lwa3.yaml")


# --------------------------------------------------------------------------- runs
def test_the_dry_run_grips_the_part_the_step_names(project):
    run = dry_run(load_sequence(write_sequence(project, UP + GRIP)), ARM, PARK)
    assert run.result.exit_code == 0, run.result.message
    grip, held = run.result.steps[4].detail, run.result.steps[5].detail
    assert grip["width_mm"] == pytest.approx(40.0, abs=0.01)
    assert grip["current_limit_a"] == pytest.approx(1.5)
    assert held["holding"] is True and run.result.steps[7].detail["holding"] is False
    assert any("the part between the jaws" in n for n in run.result.not_verified)


def sim_run(tmp_path: Path, monkeypatch, steps: str, part_mm: float):
    monkeypatch.setenv("SEQRUN_SIM_OPTIONS", f"gripper_module=8 gripper_part_mm={part_mm}")
    root = make_project(tmp_path / "p")
    write_sequence(root, UP + steps, "g.yaml")
    return run_on_sim("g", tmp_path, root=root)


def test_no_part_the_jaws_close_fully_and_the_grip_fails_with_a_halt(tmp_path, monkeypatch):
    sim = sim_run(tmp_path, monkeypatch, GRIP, 0.0)
    result = sim.outcome.result
    assert result.exit_code == 3 and result.steps[4].status == "failed"
    assert result.message == ("grip: the jaws closed to 0.0 mm, past the part (40 ± 2 mm): "
                              "no part between the jaws")
    assert result.fault["cause"] == "grip_failed" and result.fault["halt_confirmed"] is True


def test_a_part_wider_than_expected_stops_the_jaws_short(tmp_path, monkeypatch):
    sim = sim_run(tmp_path, monkeypatch, GRIP, 50.0)
    assert sim.outcome.result.exit_code == 3
    assert "stopped at 50.0 mm, short of the part" in sim.outcome.result.message


def test_the_driver_speaks_metres_and_amperes_to_the_module(tmp_path, monkeypatch):
    sim = sim_run(tmp_path, monkeypatch, GRIP, 40.0)
    assert sim.outcome.result.exit_code == 0, sim.outcome.result.message
    sent = [m for m in read_trace(sim.outcome.log_dir) if not m.is_rx and m.arbitration_id == 0x0E8]
    framp = [struct.unpack("<f", bytes(m.data[2:6]))[0] for m in sent
             if bytes(m.data[:2]) == b"\x0b\x0e"]
    assert framp == pytest.approx([0.060, 0.0, 0.060])  # release 60 mm, grip (close), release
    max_cur = [struct.unpack("<f", bytes(m.data[2:6]))[0] for m in sent
               if bytes(m.data[:2]) == b"\x08\x4c"]
    assert max_cur == pytest.approx([1.5])  # 100 N through the arm file's table
    assert sim.sim.module(8).position() == pytest.approx(0.060, abs=1e-4)


def test_a_gripper_not_homed_is_no_fault_and_a_halted_one_is():
    """A module powers on not homed with its brake on (thesis 5.1): that reads as not homed,
    not as a fault, though the drive refuses motion until Home; HALTED is a fault."""
    from seqrun.drivers.powercube.gripper import reading
    from seqrun.powercube.protocol import StateFlag

    power_on = reading(0.07, 0.0, int(StateFlag.BRAKEACTIVE | StateFlag.RAMP_END))
    assert (power_on.homed, power_on.faulted, power_on.ready) == (False, False, False)
    assert power_on.width_mm == pytest.approx(70.0)
    homed = reading(0.07, 0.0, int(StateFlag.HOME_OK | StateFlag.RAMP_END))
    assert (homed.homed, homed.faulted, homed.ready) == (True, False, True)
    halted = reading(0.07, 0.0, int(StateFlag.HOME_OK | StateFlag.HALTED))
    assert (halted.faulted, halted.ready) == (True, False)
    assert "HALTED" in halted.text
