"""Issue 39, item 3: monitors on the whole sequence (its top-level ``monitors:``, watched in
every step beside the step's own) and ``action: stop`` (a controlled stop of the motion
under way, then the same fault as ``halt``)."""

from __future__ import annotations

import pytest

from projecttree import shipped_arm
from runfolder import RunFolder
from seqrun.errors import SequenceInvalid
from seqrun.sequence.loader import load_sequence
from seqrun.sequence.validation import validate_sequence
from simrun import run_on_sim

ARM = shipped_arm()
UP = "- reset\n- home\n- set_limits\n"


def write(project, name: str, monitors: str, steps: str = UP + "- move: totem\n"):
    """A sequence whose ``monitors:`` block (lines 3 on) comes before its steps."""
    path = project / "sequences" / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(f"name: T\ndescription: test\nmonitors:\n{monitors}steps:\n{steps}",
                    encoding="utf-8")
    return path


def tripped_events(sim) -> list[dict]:
    return [e for e in RunFolder(sim.outcome.log_dir).events()
            if e["type"] == "monitor_tripped"]


def test_a_sequence_monitor_is_checked_where_it_is_written(project):
    path = write(project, "s.yaml", '  - while: "pos_deg[9] > 1"\n'
                                    '  - {while: "gripper.holding"}\n')
    errors = [str(e) for e in validate_sequence(load_sequence(path), ARM).errors]
    assert any(e.endswith("s.yaml:4:12: joint number 9 is not one of the arm's (1 to 7) "
                          "(at column 9 of 'pos_deg[9] > 1')") for e in errors), errors
    assert any("s.yaml:5:" in e and "the gripper is not read every cycle" in e
               for e in errors), errors


def test_an_included_file_may_not_declare_monitors(project):
    write(project, "inner.yaml", '  - while: "tool.z_mm > 0"\n', UP)
    outer = project / "sequences" / "outer.yaml"
    outer.write_text("name: T\ndescription: test\nsteps:\n- include: inner.yaml\n",
                     encoding="utf-8")
    with pytest.raises(SequenceInvalid, match=r"inner.yaml:3:1: an included file cannot "
                                              r"declare monitors"):
        load_sequence(outer)


def test_a_sequence_monitor_watches_every_step_and_halts_with_exit_3(tmp_path, project):
    """Totem raises the tool far above 500 mm: the sequence's monitor trips in the move,
    though the move itself has no monitor."""
    write(project, "high.yaml", '  - {while: "tool.z_mm < 500", message: keep it low}\n')
    sim = run_on_sim("high", tmp_path, root=project)
    result = sim.outcome.result
    assert result.exit_code == 3 and result.fault["halt_confirmed"] is True
    assert result.fault["cause"] == "monitor"
    assert result.message.startswith("sequence monitor 'tool.z_mm < 500' (keep it low) did "
                                     "not hold: tool.z_mm = ")
    (event,) = tripped_events(sim)
    assert event["scope"] == "sequence" and event["action"] == "halt"


def test_a_sequence_monitor_that_holds_and_a_warning_one_let_the_run_pass(tmp_path, project):
    write(project, "ok.yaml", '  - while: "tool.z_mm > -2000"\n'
                              '  - {while: "tool.z_mm < 500", action: warn}\n')
    sim = run_on_sim("ok", tmp_path, root=project)
    assert sim.outcome.result.exit_code == 0, sim.outcome.result.message
    (event,) = tripped_events(sim)
    assert event["action"] == "warn" and event["scope"] == "sequence"


def test_a_stop_monitor_brakes_the_move_smoothly_before_the_halt(tmp_path, project):
    """``action: stop``: the move is brought to a controlled stop (a ruckig stop streamed
    to the modules), then the fault's Halt; ``halt`` halts at once."""
    for action in ("halt", "stop"):
        write(project, f"{action}.yaml", f'  - {{while: "tool.z_mm < 500", action: {action}}}\n')
    halted = run_on_sim("halt", tmp_path / "halt", root=project)
    stopped = run_on_sim("stop", tmp_path / "stop", root=project)
    for sim in (halted, stopped):
        assert sim.outcome.result.exit_code == 3
        assert sim.outcome.result.fault["halt_confirmed"] is True
    kinds = [e["type"] for e in RunFolder(stopped.outcome.log_dir).events()]
    assert "controlled_stop" in kinds and "holding" in kinds
    assert kinds.index("monitor_tripped") < kinds.index("controlled_stop") \
        < kinds.index("holding") < kinds.index("fault")
    assert "controlled_stop" not in [e["type"] for e in
                                    RunFolder(halted.outcome.log_dir).events()]


def test_the_dry_run_trips_a_sequence_monitor_as_the_run_does(project):
    from seqrun.service.dryrun import dry_run

    path = write(project, "dry.yaml", '  - while: "tool.z_mm < 500"\n')
    loaded = load_sequence(path)
    PARK = {"j1": 0, "j2": -90, "j3": 0, "j4": -120.32, "j5": 0, "j6": 115.74, "j7": 0}
    result = dry_run(loaded, ARM, PARK).result
    assert result.exit_code == 3 and "sequence monitor 'tool.z_mm < 500'" in result.message
