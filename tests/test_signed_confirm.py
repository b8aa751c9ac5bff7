"""Signed confirms and breakpoints (issue 40, items 4 and 5, a first slice): only a person
at the run answers them (never --yes); a signature names who, as what, when and the
validated inputs, in record.json, report.json and report.html; a breakpoint stops between
steps and a "no" ends the run as an operator abort."""

from __future__ import annotations

import datetime as dt
import json
import shutil
from pathlib import Path

from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers every command)
from projecttree import ROOT
from seqrun.cli.app import app
from seqrun.service.runlog import read_events
from seqrun.service.runner import inputs_digest

SIGNED = "  - confirm: {prompt: 'Is the desk clear?', role: test conductor, sign: true}\n"


def campaign(tmp_path, steps: str, *, startup: bool = False):
    root = tmp_path / "campaign"
    for folder in ("sequences", "arms", "poses"):
        shutil.copytree(ROOT / folder, root / folder)
    path = root / "sequences" / "signed.yaml"
    path.write_text("name: signed\nsteps:\n" + ("  - include: startup.yaml\n" if startup
                                                else "") + steps)
    return path


def run(path, folder, stdin: str, *extra: str):
    return CliRunner().invoke(app, ["run", str(path), "--virtual-time", "--plain",
                                    "--log-dir", str(folder), *extra], input=stdin)


def test_a_signed_confirm_keeps_who_as_what_when_and_the_inputs(tmp_path):
    path = campaign(tmp_path, SIGNED)
    before = dt.datetime.now(dt.timezone.utc).replace(microsecond=0)
    # yes, then an empty name (asked again), then the name
    result = run(path, tmp_path / "run", "y\n   \n  Ada   Lovelace \n")
    after = dt.datetime.now(dt.timezone.utc)
    assert result.exit_code == 0, result.output
    assert result.output.count("your name:") == 2
    assert "needs the name of who gives it" in result.output
    report = json.loads((tmp_path / "run" / "report.json").read_text())
    [step] = report["steps"]
    assert step["signed_by"] == "Ada Lovelace"
    assert step["signed_role"] == "test conductor"
    signed_at = dt.datetime.fromisoformat(step["signed_at_utc"].replace("Z", "+00:00"))
    assert before <= signed_at <= after
    # the hash of the inputs the run was validated from (report.json lists them)
    assert step["inputs_sha256"] == inputs_digest(report["inputs"])
    assert len(step["inputs_sha256"]) == 64
    record = json.loads((tmp_path / "run" / "record.json").read_text())
    assert record["signatures"] == [{"step": 1, "text": step["label"],
                                     **{k: step[k] for k in ("signed_by", "signed_role",
                                                             "signed_at_utc",
                                                             "inputs_sha256")}}]
    html = (tmp_path / "run" / "report.html").read_text()
    assert "Ada Lovelace (test conductor)" in html
    assert step["signed_at_utc"] in html and step["inputs_sha256"] in html
    events = read_events(tmp_path / "run")
    assert [e["signed_by"] for e in events if e["type"] == "confirm_signed"] == ["Ada Lovelace"]


def test_no_name_is_no_signature_and_ends_the_run(tmp_path):
    path = campaign(tmp_path, SIGNED)
    result = run(path, tmp_path / "run", "y\n")   # the input ends where the name is asked
    assert result.exit_code == 130, result.output
    report = json.loads((tmp_path / "run" / "report.json").read_text())
    assert report["steps"][0]["status"] != "passed"
    assert "signatures" not in json.loads((tmp_path / "run" / "record.json").read_text())


def test_yes_never_answers_a_signed_confirm_or_a_breakpoint(tmp_path):
    for steps in (SIGNED, "  - wait: {seconds: 1, breakpoint: true}\n"):
        path = campaign(tmp_path / str(len(steps)), steps)
        result = run(path, tmp_path / "run", "y\nAda\ny\n", "--yes")
        assert result.exit_code == 2, result.output
        [line] = result.output.strip().splitlines()[-1:]
        assert "--yes" in line and "nothing was sent" in line and "signed.yaml:3:5" in line
        assert not (tmp_path / "run").exists()


def test_a_plain_confirm_is_still_answered_by_yes(tmp_path):
    path = campaign(tmp_path, "  - confirm: Is the desk clear?\n")
    result = run(path, tmp_path / "run", "", "--yes")
    assert result.exit_code == 0, result.output
    assert "signed_by" not in json.loads((tmp_path / "run" / "report.json").read_text())[
        "steps"][0]


def test_a_breakpoint_no_is_an_operator_abort_before_the_step(tmp_path):
    path = campaign(tmp_path, "  - move: {joints: {j1: 2}}\n"
                              "  - move: {joints: {j1: 0}, breakpoint: true}\n",
                    startup=True)
    result = run(path, tmp_path / "run", "n\n", "--no-report")
    assert result.exit_code == 130, result.output
    assert result.output.count("Continue? [y/N]") == 1
    folder = tmp_path / "run"
    steps = json.loads((folder / "report.json").read_text())["steps"]
    assert [s["status"] for s in steps] == ["passed"] * 4 + ["aborted"]
    events = read_events(folder)
    reached = next(i for i, e in enumerate(events) if e["type"] == "breakpoint_reached")
    assert events[reached]["step"] == 5
    answered = [e for e in events if e["type"] == "breakpoint_answered"]
    assert [(e["step"], e["go_on"]) for e in answered] == [(5, False)]
    # nothing moved after: step 5 never started, no plan was streamed after the question
    later = {e["type"] for e in events[reached:]}
    assert "step_started" not in later
    assert not any(t.startswith("move") or t == "plan" for t in later), later


def test_a_breakpoint_yes_goes_on(tmp_path):
    path = campaign(tmp_path, "  - wait: {seconds: 0.5, breakpoint: true}\n")
    result = run(path, tmp_path / "run", "y\n", "--no-report")
    assert result.exit_code == 0, result.output
    events = read_events(tmp_path / "run")
    assert [e["go_on"] for e in events if e["type"] == "breakpoint_answered"] == [True]


def test_validate_lists_breakpoints_and_signed_confirms_as_not_verified(tmp_path):
    path = campaign(tmp_path, SIGNED + "  - wait: {seconds: 0.5, breakpoint: true}\n")
    result = CliRunner().invoke(app, ["validate", str(path)])
    assert result.exit_code == 0, result.output
    unverified = result.output.split("not verified:")[1]
    assert "step 1: signed operator confirmation 'Is the desk clear?' by the test " \
           "conductor" in unverified
    assert "step 2: breakpoint before" in unverified


def test_sign_and_breakpoint_are_strict_booleans(tmp_path):
    for steps, col in (("  - confirm: {prompt: 'Clear?', sign: 'yes'}\n", 39),
                       ("  - wait: {seconds: 1, breakpoint: 'yes'}\n", 36),
                       ("  - include: {file: park.yaml, breakpoint: true}\n", 14)):
        path = campaign(tmp_path / str(col) / str(len(steps)), steps)
        result = CliRunner().invoke(app, ["validate", str(path)])
        assert result.exit_code == 1, result.output
        assert f"signed.yaml:3:{col}" in result.output, result.output


def test_a_run_of_several_arms_refuses_them_before_anything_is_sent(tmp_path):
    root = tmp_path / "two-arms"
    shutil.copytree(ROOT / "examples" / "two-arms", root)
    path = root / "sequences" / "hold_and_approach.yaml"
    text = path.read_text()
    assert "  - confirm: Is the floor between the arms clear?\n" in text
    path.write_text(text.replace("  - confirm: Is the floor between the arms clear?\n",
                                 "  - confirm: {prompt: 'Is the floor clear?', sign: true}\n"))
    result = CliRunner().invoke(app, ["run", str(path), "--virtual-time", "--plain",
                                      "--log-dir", str(tmp_path / "run")], input="y\nAda\n")
    assert result.exit_code == 2, result.output
    assert "is a signed confirm: not in a run of several arms yet" in result.output
    assert not (tmp_path / "run").exists()


# ------------------------------------------------------------- the session (the console's way)
def test_the_session_asks_a_signed_confirm_and_a_breakpoint_as_questions(tmp_path):
    import threading

    from seqrun.arm.description import load_arm
    from seqrun.clock import VirtualClock
    from seqrun.errors import Refused
    from seqrun.service import ArmSession
    from seqrun.service.connection import open_connection

    path = campaign(tmp_path, SIGNED + "  - wait: {seconds: 0.5, breakpoint: true}\n")
    connection = open_connection(force_sim=True, clock=VirtualClock())
    session = ArmSession(load_arm(ROOT / "arms" / "lwa3.yaml"), connection, status_hz=0,
                         log_root=tmp_path / "runs", poses_dir=ROOT / "poses")
    try:
        sub = session.subscribe(maxsize=100_000)
        asked: list = []
        refused: list[str] = []

        def answer() -> None:
            for event in sub:
                if event.type == "confirm_requested":
                    asked.append(event)
                    if event.sign:
                        try:   # a yes without a name is refused: the question stays open
                            session.answer(event.question_id, True, "  ")
                        except Refused as exc:
                            refused.append(str(exc))
                        session.answer(event.question_id, True, "Grace Hopper")
                    else:
                        session.answer(event.question_id, True)
                if event.type == "activity_finished":
                    return

        answering = threading.Thread(target=answer, daemon=True)
        answering.start()
        # assume_yes answers plain confirms only: these two are still asked
        result = session.run_sequence(path, assume_yes=True).wait(120)
        answering.join(10)
        assert result.ok, result.message
        assert [(e.sign, e.role) for e in asked] == [(True, "test conductor"), (None, None)]
        assert "Breakpoint before step 2" in asked[1].text
        assert refused == ["answer: a signed question needs the name of who answers"]
        step = json.loads((Path(result.run_dir) / "report.json").read_text())["steps"][0]
        assert (step["signed_by"], step["signed_role"]) == ("Grace Hopper", "test conductor")
        record = json.loads((Path(result.run_dir) / "record.json").read_text())
        assert record["signatures"][0]["signed_by"] == "Grace Hopper"
    finally:
        session.close()
