"""move_velocity: the thesis GUI's velocity mode, never open-ended.

Validation refuses a velocity move without a duration or an envelope (file:line:col), an
envelope beyond the limits and a velocity whose stop leaves the envelope (a wrong sign);
a dry run follows it on the simulator (FVEL, virtual time) inside its envelope; a run that
stops talking mid-move leaves the modules' watchdog to stop the joints.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from projecttree import make_project, shipped_arm, write_sequence
from seqrun.arm.velocity import VelocityPlan, stop_position
from seqrun.errors import SequenceInvalid
from seqrun.powercube.protocol import ConfigFlag, ParamId, StateFlag
from seqrun.service.dryrun import dry_run
from seqrun.sequence.loader import load_sequence
from seqrun.sequence.validation import validate_sequence
from seqrun.service.runlog import read_trace
from seqrun.sim.module import ModuleOptions
from simrun import run_on_sim
from runfolder import RunFolder

ARM = shipped_arm()
PARK = {"j1": 0, "j2": -90, "j3": 0, "j4": -120.32, "j5": 0, "j6": 115.74, "j7": 0}
UP = "- reset\n- home\n- set_limits\n- move: totem\n"  # lines 4-7: the step is on line 8


def load(project: Path, step: str):
    return load_sequence(write_sequence(project, UP + step))


def findings(project: Path, step: str) -> list[str]:
    result = validate_sequence(load(project, step), ARM, PARK)
    return [f"{e.line}:{e.column}: {e.message}" for e in result.errors]


def schema_errors(project: Path, step: str) -> list[str]:
    with pytest.raises(SequenceInvalid) as info:
        load(project, step)
    return [f"{e.line}:{e.column}: {e.message}" for e in info.value.errors]


# --------------------------------------------------------------------------- refusals
def test_a_velocity_move_without_a_duration_is_refused_where_it_is_written(project):
    [error] = schema_errors(project, "- move_velocity: {velocity_deg_s: {j1: 5}, "
                                     "envelope_deg: {j1: [-5, 15]}}\n")
    assert error.startswith("8:18:") and "duration_s" in error


def test_a_velocity_move_without_an_envelope_is_refused(project):
    [error] = schema_errors(project, "- move_velocity: {velocity_deg_s: {j1: 5}, "
                                     "duration_s: 2}\n")
    assert error.startswith("8:18:") and "envelope_deg" in error


def test_every_moving_joint_needs_its_envelope(project):
    [error] = schema_errors(project, "- move_velocity: {velocity_deg_s: {j1: 5, j2: 1}, "
                                     "duration_s: 1, envelope_deg: {j1: [-5, 15]}}\n")
    assert "envelope_deg has no [min, max] for j2" in error


def test_a_zero_or_negative_duration_is_refused(project):
    [error] = schema_errors(project, "- move_velocity: {velocity_deg_s: {j1: 5}, "
                                     "duration_s: 0, envelope_deg: {j1: [-5, 15]}}\n")
    assert "duration_s" in error or "greater than 0" in error


def test_an_envelope_beyond_the_limits_is_refused(project):
    [error] = findings(project, "- move_velocity: {velocity_deg_s: {j1: 5}, duration_s: 2, "
                                "envelope_deg: {j1: [-5, 200]}}\n")
    assert error.startswith("8:78:")
    assert "envelope_deg of j1 -5…200 goes beyond the limits in force -180…180" in error


def test_a_wrong_sign_that_leaves_the_envelope_is_refused_before_anything_moves(project):
    [error] = findings(project, "- move_velocity: {velocity_deg_s: {j1: -5}, duration_s: 2, "
                                "envelope_deg: {j1: [-5, 15]}}\n")
    assert error.startswith("8:40:")  # at j1's velocity
    assert "comes to rest at -10°" in error and "outside its envelope -5…15" in error
    assert "check the sign" in error


def test_a_duration_whose_stop_leaves_the_envelope_is_refused(project):
    # 5 deg/s for 3 s is 15 deg; the envelope ends at 15 (with the 0.2 deg margin: refused)
    [error] = findings(project, "- move_velocity: {velocity_deg_s: {j1: 5}, duration_s: 3, "
                                "envelope_deg: {j1: [-5, 15]}}\n")
    assert "comes to rest at 15°" in error


def test_a_velocity_above_the_arm_maximum_is_refused(project):
    [error] = findings(project, "- move_velocity: {velocity_deg_s: {j1: -50}, duration_s: 0.1, "
                                "envelope_deg: {j1: [-20, 20]}}\n")
    assert "velocity_deg_s of j1 -50 deg/s is above its maximum 30 deg/s" in error


def test_a_velocity_move_before_home_is_refused(project):
    path = write_sequence(project, "- move_velocity: {velocity_deg_s: {j1: 5}, duration_s: 1, "
                                   "envelope_deg: {j1: [-5, 15]}}\n")
    result = validate_sequence(load_sequence(path), ARM, PARK)
    assert any("move before home" in e.message for e in result.errors)


def test_the_stop_is_tracked_for_the_steps_after(project):
    result = validate_sequence(load(project, "- move_velocity: {velocity_deg_s: {j1: 5}, "
                                             "duration_s: 2, envelope_deg: {j1: [-5, 15]}}\n"),
                               ARM, PARK)
    assert result.errors == []
    assert result.final_deg["j1"] == pytest.approx(10.0)


# --------------------------------------------------------------------------- the plan
def test_the_plan_ramps_holds_and_brakes_to_its_stop():
    plan = VelocityPlan.plan([0.0, 1.0], [0.5, 0.0], [2.0, 2.0], 3.0)
    assert plan.active == (0,)
    assert plan.duration == pytest.approx(3.25)
    assert plan.target == pytest.approx([1.5, 1.0])
    assert plan.at(1.0)[1][0] == pytest.approx(0.5)
    assert plan.at(3.25)[0][0] == pytest.approx(1.5)
    # braking from anywhere ends at the plan's stop
    for t in np.linspace(3.0, 3.25, 6):
        pos, vel, _ = plan.at(float(t))
        assert stop_position(pos[0], vel[0], 2.0) == pytest.approx(1.5)


def test_a_short_duration_gives_a_triangle():
    plan = VelocityPlan.plan([0.0], [1.0], [1.0], 0.5)
    assert plan.profiles[0].velocity == pytest.approx(0.5)
    assert plan.duration == pytest.approx(1.0)
    assert plan.target[0] == pytest.approx(0.25)


# --------------------------------------------------------------------------- runs
STEP = ("- move_velocity: {velocity_deg_s: {j1: 5, j4: -3}, duration_s: 2, "
        "envelope_deg: {j1: [-5, 15], j4: [-10, 5]}}\n")


def test_a_dry_run_follows_the_velocities_inside_the_envelope(project):
    run = dry_run(load(project, STEP), ARM, PARK)
    assert run.result.exit_code == 0, run.result.message
    step = run.result.steps[-1]
    assert step.detail["command_mode"] == "velocity"
    assert step.detail["stop_deg"][0] == pytest.approx(10.0)
    assert step.detail["stop_deg"][3] == pytest.approx(-6.0)


def events(folder: Path) -> list[dict]:
    return RunFolder(folder).events()


def test_the_velocity_move_goes_out_as_fvel_with_the_watchdog_armed(tmp_path):
    root = make_project(tmp_path / "p")
    write_sequence(root, UP + STEP, "v.yaml")
    sim = run_on_sim("v", tmp_path, root=root)
    assert sim.outcome.result.exit_code == 0, sim.outcome.result.message
    # at virtual time on the simulator, every cycle of the move inside its envelope
    measured = np.array([e["measured_deg"] for e in events(sim.outcome.log_dir)
                         if e["type"] == "setpoint" and e.get("step") == 5])
    assert len(measured) > 150
    assert -5 <= measured[:, 0].min() and measured[:, 0].max() <= 15
    assert -10 <= measured[:, 3].min() and measured[:, 3].max() <= 5
    assert measured[-1, [0, 3]] == pytest.approx([10.0, -6.0], abs=0.2)
    sent = [m for m in read_trace(sim.outcome.log_dir) if not m.is_rx]
    fvel = [m for m in sent if m.arbitration_id == 0x0E1 and bytes(m.data[:2]) == b"\x0b\x11"]
    assert len(fvel) > 150  # one FVEL_ACK per cycle for about 2 s
    first_fvel = sent.index(fvel[0])
    refreshes = [k for k, m in enumerate(sent)
                 if m.arbitration_id == 0x100 and bytes(m.data[:1]) == b"\x07"]
    assert refreshes and refreshes[0] < first_fvel  # armed before the first FVEL
    # FVEL 0 at the end: nothing left creeping; the watchdog disarmed: no fault later
    later = sim.connection.clock.now() + 1.0
    assert sim.sim.module(1).velocity(later) == 0.0 and sim.sim.module(4).velocity(later) == 0.0
    assert fvel[-1].data[2:6] == b"\x00\x00\x00\x00"
    assert not sim.sim.module(1).state() & StateFlag.ERROR
    assert not int(sim.sim.module(1).parameter(ParamId.CONFIG)) & ConfigFlag.WATCHDOG_ENABLE


def test_a_silent_seqrun_is_stopped_by_the_watchdog_within_its_bound(tmp_path):
    """Mid-move the loop stops talking (0.5 s without a frame). The modules' watchdog
    stops the joints: j1 (5 deg/s) travels at most v * (watchdog timeout + refresh
    period) after its last frame, then the run faults with a Halt and a non-zero exit."""
    root = make_project(tmp_path / "p")
    write_sequence(root, UP + STEP, "v.yaml")
    stall: dict[str, float] = {}

    def attach(executor) -> None:
        check_guards, calls = executor.check_guards, [0]

        def silent(m):
            step = executor.current_step
            calls[0] += step is not None and step.kind == "move_velocity"
            if calls[0] == 100 and not stall:  # 1 s into the velocity move, at 5 deg/s
                stall["from_deg"] = float(m.user_deg[0])
                stall["t"] = executor.clock.now()
                executor.clock.sleep(0.5)          # no frame, no refresh for 0.5 s
            return check_guards(m)

        executor.check_guards = silent

    sim = run_on_sim("v", tmp_path, root=root, on_executor=attach)
    assert stall, "the stall never came: the move is shorter than expected"
    assert sim.outcome.result.exit_code == 3
    module = sim.sim.module(1)
    moved = math.degrees(module.position()) - ARM.joint("j1").offset_deg - stall["from_deg"]
    timeout = ModuleOptions().watchdog_timeout
    bound = 5.0 * (timeout + ARM.can.watchdog.refresh_period_s)
    assert 0 <= moved <= bound, (moved, bound)
    assert sim.outcome.result.fault["halt_sent"] is True
    assert "COMM_ERROR" in sim.outcome.result.message, sim.outcome.result.message


# --------------------------------------------------------------------------- the cycle check
class _Reading:
    def __init__(self, t: float, j1: float) -> None:
        self.t = t
        self.user_deg = np.array([j1, 0, 0, 0, 0, 0, 0], float)


class _Context:
    """Just enough of a StepContext to run the handler: ``follow`` feeds the step's path
    check the readings given (a joint running ahead of its plan)."""

    arm, speed = ARM, 1.0
    limits_in_force = type("L", (), {"maxima": staticmethod(lambda: ({}, {}))})()

    def __init__(self, readings: list[_Reading]) -> None:
        self.readings = readings
        self.seen: list[float] = []

    def read_arm(self):
        return self.readings[0]

    def emit(self, type_: str, **data) -> None:
        pass

    def follow(self, plan, *, path_check, **kw):
        for m in self.readings[1:]:
            path_check(m)
            self.seen.append(float(m.user_deg[0]))
        return {}


def handler_step(project):
    loaded = load(project, "- move_velocity: {velocity_deg_s: {j1: 5}, duration_s: 2, "
                           "envelope_deg: {j1: [-5, 15]}}\n")
    return loaded.steps[-1]


def test_every_cycle_halts_a_joint_whose_stop_would_leave_the_envelope(project):
    from seqrun.errors import RunAborted
    from seqrun.steps.move_velocity import run

    # A joint running on (further than planned) at 5 deg/s; braking at 60 deg/s^2 takes
    # 0.21 deg: at 14.75 it would stop at 14.96 (in), at 14.80 at 15.01 (out): the run
    # stops there, before the joint itself reaches the edge.
    readings = [_Reading(0.0, 0.0), _Reading(2.94, 14.70), _Reading(2.95, 14.75),
                _Reading(2.96, 14.80), _Reading(2.97, 14.85)]
    ex = _Context(readings)
    with pytest.raises(RunAborted, match=r"j1 at 14.80° moving \+5.00 deg/s would stop at "
                                         r"15.01°, outside its envelope -5…15"):
        run(handler_step(project), ex)
    assert ex.seen == [14.7, 14.75]
