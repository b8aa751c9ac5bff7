"""The dry run is the run (issue 29): ``seqrun validate``'s dry run reports every figure
``seqrun run --virtual-time`` reports, under every simulator fault it can rehearse.

Each case runs the shipped sequence twice on a fresh simulated arm powered on at Park:
:func:`seqrun.service.dryrun.dry_run` (what ``seqrun validate [--sim-fault SPEC]`` calls) and the
real command ``seqrun run FILE --virtual-time --yes --plain --no-report [--sim-fault SPEC]``
in process, then compares the dry run's report with the run's report.json: verdict, exit
code and message, the fault record (cause, module, failing step, Halt), every step's status,
duration, planned duration and figures (peak velocities, following and final errors, ...)
and the lowest guard heights. The one field allowed to differ is a confirm step's
``confirmed`` (the dry run assumes the answer, the run got it).

Also: ``seqrun validate --sim-fault`` on the command line, and an old arm file that still
has ``control.dry_run_cycle_hz``.
"""

from __future__ import annotations

import json
import shutil

import pytest
from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers the commands on the app)
from projecttree import ROOT
from seqrun.arm.description import load_arm
from seqrun.cli.app import app
from seqrun.service.dryrun import dry_run
from seqrun.sequence.loader import load_sequence
from seqrun.sim.faults import FAULT_KINDS, parse_fault_spec
from seqrun.defaults import START_POSE
from seqrun.arm.poses import pose_joints_deg

SEQUENCES = ("opsafe", "totem")
#: Every fault kind on j4 (moving in both sequences) during the first move, and random
#: acknowledge losses: often (fails at once), rare on a read-only module (retried, then a
#: loss inside the quarantine halts the run at ~6.9 s) and rarer (retried, passes).
FAULTS = (None, "4:tow_error@3", "4:halt@3", "4:no_ack@3", "4:stuck@3", "4:missing@3",
          "4:drop_acks=0.5@0", "7:drop_acks=0.01@0", "7:drop_acks=0.003@0", "all:halt@10")
#: The fast tier's share (CI runs them all).
FAST = {("opsafe", None), ("totem", "4:tow_error@3"), ("opsafe", "7:drop_acks=0.01@0"),
        ("totem", "4:stuck@3")}
#: Differs by design: the dry run assumes an operator's yes, the run was given it.
ASSUMED = {"confirmed"}


def test_every_fault_kind_is_rehearsed():
    assert {parse_fault_spec(f).kind for f in FAULTS if f} == set(FAULT_KINDS)


def _dry_run(name: str, spec: str | None):
    loaded = load_sequence(ROOT / "sequences" / f"{name}.yaml")
    arm = load_arm(loaded.arm_path)
    start = pose_joints_deg(START_POSE, loaded.pose_path or loaded.poses_dir)
    return dry_run(loaded, arm, start, faults=[parse_fault_spec(spec)] if spec else [])


def _run(name: str, spec: str | None, folder) -> tuple[int, dict]:
    args = ["run", str(ROOT / "sequences" / f"{name}.yaml"), "--virtual-time", "--yes",
            "--plain", "--no-report", "--log-dir", str(folder)]
    if spec:
        args += ["--sim-fault", spec]
    result = CliRunner().invoke(app, args)
    assert result.exception is None or isinstance(result.exception, SystemExit), result.output
    return result.exit_code, json.loads((folder / "report.json").read_text())


@pytest.mark.parametrize("name, spec", [
    pytest.param(name, spec, marks=() if (name, spec) in FAST else pytest.mark.slow)
    for name in SEQUENCES for spec in FAULTS])
def test_dry_run_figures_are_the_runs(name, spec, tmp_path):
    dry = _dry_run(name, spec)
    exit_code, report = _run(name, spec, tmp_path / "run")
    mine = dry.as_dict()
    assert dry.cycle_hz == load_arm(ROOT / "arms" / "lwa3.yaml").control.cycle_hz
    assert dry.faults == ([spec] if spec else [])
    assert (mine["status"], dry.result.exit_code, mine["message"]) == (
        report["status"], exit_code, report["message"])
    assert mine["fault"] == report["fault"]
    assert round(dry.simulated_s, 4) == report["duration_s"]
    assert round(dry.result.planned_duration_s, 4) == report["planned_duration_s"]
    assert mine["min_heights_mm"] == report["min_heights_mm"]
    assert len(mine["steps"]) == len(report["steps"])
    for ours, theirs in zip(mine["steps"], report["steps"]):
        assert ({k: v for k, v in ours.items() if k not in ASSUMED}
                == {k: v for k, v in theirs.items() if k not in ASSUMED}), ours["number"]
    moves = [s for s in mine["steps"] if s["kind"] == "move" and s["status"] != "pending"]
    assert all("max_following_error_deg" in s for s in moves)  # the figures were compared
    assert moves or spec  # (a clean run moves; 4:drop_acks=0.5 fails before any move)


def _validate(*args: str):
    return CliRunner().invoke(app, ["validate", *args])


def test_validate_rehearses_a_fault():
    result = _validate(str(ROOT / "sequences" / "opsafe.yaml"), "--sim-fault", "4:tow_error@3",
                       "--json")
    assert result.exit_code == 3, result.output  # as `seqrun run --sim-fault` ends
    report = json.loads(result.output)
    assert report["valid"] is False and report["errors"] == []  # the file is fine
    run = report["dry_run"]
    assert run["faults"] == ["4:tow_error@3"] and run["cycle_hz"] == 100
    assert run["fault"]["cause"] == "tow_error" and run["fault"]["module"] == 4
    assert run["fault"]["step"] == 5 and run["fault"]["halt_sent"] is True
    human = _validate(str(ROOT / "sequences" / "opsafe.yaml"), "--sim-fault", "4:tow_error@3")
    assert human.exit_code == 3
    assert "100 Hz loop, rehearsing 4:tow_error@3): FAILED" in human.output
    assert "fault: module 4 (j4): ERROR|HALTED|TOW_ERROR" in human.output


def test_validate_without_a_fault_passes_at_the_run_rate():
    result = _validate(str(ROOT / "sequences" / "opsafe.yaml"), "--json")
    assert result.exit_code == 0, result.output
    run = json.loads(result.output)["dry_run"]
    assert run["passed"] and run["faults"] == [] and run["cycle_hz"] == 100


@pytest.mark.parametrize("spec, message", [
    ("4:bogus@3", "--sim-fault '4:bogus@3': fault spec '4:bogus@3': unknown kind 'bogus'"),
    ("9:halt@1", "--sim-fault '9:halt@1': the arm has no module 9 (modules 1, 2, 3, 4, 5, 6, 7)"),
    ("4:halt", "--sim-fault '4:halt': fault spec '4:halt': missing '@SECONDS'"),
])
def test_validate_refuses_a_bad_fault_in_one_line(spec, message):
    result = _validate(str(ROOT / "sequences" / "opsafe.yaml"), "--sim-fault", spec)
    assert result.exit_code == 2
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {message}"), result.output
    assert "Traceback" not in result.output


def test_validate_static_takes_no_fault():
    result = _validate(str(ROOT / "sequences" / "opsafe.yaml"), "--static",
                       "--sim-fault", "4:halt@1")
    assert result.exit_code == 2
    assert "--sim-fault rehearses a fault in the dry run: leave out --static" in result.output


def test_several_files_rehearse_the_fault_in_every_dry_run():
    result = _validate(str(ROOT / "sequences" / "opsafe.yaml"),
                       str(ROOT / "sequences" / "totem.yaml"), "--sim-fault", "4:tow_error@3")
    assert result.exit_code == 3, result.output
    rows = [line for line in result.output.splitlines() if "  dry run failed  3.01 s" in line]
    assert len(rows) == 2, result.output
    assert result.output.count("dry run failed: module 4 (j4): ERROR|HALTED|TOW_ERROR") == 2


def test_an_old_arm_file_with_dry_run_cycle_hz_still_loads_with_a_note(tmp_path):
    """An engineer's campaign arm file from before issue 29: it keeps working (the real
    runs must not stop over a key that only ever slowed dry runs), the value is ignored
    and ``seqrun validate`` says so, where the line is."""
    for folder in ("arms", "poses", "sequences"):
        shutil.copytree(ROOT / folder, tmp_path / folder)
    arm_file = tmp_path / "arms" / "lwa3.yaml"
    lines = arm_file.read_text().splitlines(keepends=True)
    at = next(i for i, line in enumerate(lines) if line.strip().startswith("cycle_hz:"))
    lines.insert(at + 1, "  dry_run_cycle_hz: 10\n")
    arm_file.write_text("".join(lines))
    arm = load_arm(arm_file)
    assert [str(n) for n in arm.notes] == [
        f"{arm.source_file}:{at + 2}:3: control.dry_run_cycle_hz is no longer used and is "
        "ignored: the dry run streams at control.cycle_hz (100 Hz) like a run, so that its "
        "figures are the run's; delete this line"]
    result = _validate(str(tmp_path / "sequences" / "opsafe.yaml"), "--json")
    assert result.exit_code == 0, result.output
    report = json.loads(result.output)
    assert report["dry_run"]["cycle_hz"] == 100
    notes = [n for n in report["notes"] if "dry_run_cycle_hz" in n["message"]]
    assert [(n["line"], n["column"]) for n in notes] == [(at + 2, 3)]
    human = _validate(str(tmp_path / "sequences" / "opsafe.yaml"), "--static")
    assert f"lwa3.yaml:{at + 2}:3: note: control.dry_run_cycle_hz is no longer used" in human.output
    folder = _validate(str(tmp_path / "arms"))
    assert folder.exit_code == 0 and "0 errors, 1 note" in folder.output
    assert load_arm(ROOT / "arms" / "lwa3.yaml").notes == []
