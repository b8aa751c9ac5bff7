"""Hazard classes of motion steps (issue 40, item 4): ``hazard: normal | caution |
hazardous`` on a move, classes derived from a move's smallest planned clearance where the
arm file's ``hazards.*.within_mm`` say so, a speed cap per class (the dry run and the run
alike) and a signed confirm before a hazardous step, which --yes never answers. All at
virtual time."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers every command)
from projecttree import ROOT
from seqrun.cli.app import app
from seqrun.service.runlog import read_events

#: Park -> Totem passes the desk closest (wrist to desk 15.9 mm, link volumes); Totem ->
#: Op-safe comes no closer than 72 mm (forearm to hand).
TO_TOTEM = "  - move: {pose: totem%s}\n"
TO_OPSAFE = "  - move: {pose: opsafe%s}\n"
#: Derived classes: closer than 20 mm hazardous, than 100 mm caution.
DERIVING = ("hazards:\n  caution: {within_mm: 100}\n"
            "  hazardous: {within_mm: 20, role: test conductor}\n")


def campaign(tmp_path, steps: str, *, arm_extra: str = ""):
    root = tmp_path / "campaign"
    for folder in ("sequences", "arms", "poses"):
        shutil.copytree(ROOT / folder, root / folder)
    if arm_extra:
        arm = root / "arms" / "lwa3.yaml"
        arm.write_text(arm.read_text() + arm_extra)
    path = root / "sequences" / "hazard.yaml"
    path.write_text("name: hazard\nsteps:\n  - include: startup.yaml\n" + steps)
    return path


def run(path, folder, stdin: str = "", *extra: str, report: bool = False):
    return CliRunner().invoke(app, ["run", str(path), "--virtual-time", "--plain",
                                    *([] if report else ["--no-report"]),
                                    "--log-dir", str(folder), *extra], input=stdin)


def validate_json(path) -> dict:
    result = CliRunner().invoke(app, ["validate", "--json", str(path)])
    assert result.exit_code in (0, 1), result.output
    return json.loads(result.output)


def step_report(folder, number: int) -> dict:
    steps = json.loads((folder / "report.json").read_text())["steps"]
    return next(s for s in steps if s["number"] == number)


@pytest.mark.slow  # three runs and three dry runs at virtual time
def test_caution_caps_the_speed_in_the_dry_run_and_the_run_alike(tmp_path):
    durations = {}
    for name, extra in (("normal", ""), ("caution", ", hazard: caution"),
                        ("scaled", ", velocity_scale: 0.5")):
        path = campaign(tmp_path / name, TO_TOTEM % extra)
        folder = tmp_path / name / "run"
        result = run(path, folder)
        assert result.exit_code == 0, result.output
        step = step_report(folder, 4)
        planned = next(s for s in validate_json(path)["dry_run"]["steps"] if s["number"] == 4)
        assert planned["planned_duration_s"] == step["planned_duration_s"]
        durations[name] = step["planned_duration_s"], step["duration_s"]
        if name == "caution":
            assert step["hazard"] == "caution" and step["hazard_speed_scale"] == 0.5
        else:
            assert "hazard" not in step
    # the arm file's caution cap (default 0.5 of the velocity limits) plans the move as
    # velocity_scale 0.5 does, and it runs as long; longer than at full speed
    assert durations["caution"] == durations["scaled"]
    assert durations["caution"][0] > 1.2 * durations["normal"][0]
    assert durations["caution"][1] > 1.2 * durations["normal"][1]


def test_the_smaller_of_velocity_scale_and_the_cap_wins(tmp_path):
    planned = {}
    for name, extra in (("slow", ", velocity_scale: 0.2"),
                        ("slow_caution", ", velocity_scale: 0.2, hazard: caution")):
        data = validate_json(campaign(tmp_path / name, TO_TOTEM % extra))
        planned[name] = next(s["planned_duration_s"] for s in data["dry_run"]["steps"]
                             if s["number"] == 4)
    assert planned["slow"] == planned["slow_caution"]


def test_classes_are_derived_from_the_smallest_clearance(tmp_path):
    path = campaign(tmp_path, TO_TOTEM % "" + TO_OPSAFE % "", arm_extra=DERIVING)
    data = validate_json(path)
    assert data["valid"], data["errors"]
    hazards = {h["step"]: h for h in data["hazards"]}
    assert hazards[4]["hazard"] == "hazardous"
    assert hazards[4]["reason"].startswith("within 15.") and "wrist to desk" in hazards[4]["reason"]
    assert hazards[4]["speed_scale"] == 0.25 and hazards[4]["role"] == "test conductor"
    assert hazards[5]["hazard"] == "caution" and hazards[5]["speed_scale"] == 0.5
    result = CliRunner().invoke(app, ["validate", "--static", str(path)])
    assert result.exit_code == 0, result.output
    assert ("step 4 (" in result.output and "hazard.yaml:4:5): hazardous — within 15."
            in result.output)
    assert "speed capped at 25 %; needs a signed confirm by the test conductor" in result.output


def test_without_within_mm_nothing_is_derived(tmp_path):
    data = validate_json(campaign(tmp_path, TO_TOTEM % "" + TO_OPSAFE % ""))
    assert data["valid"] and "hazards" not in data


def test_an_explicit_class_lower_than_the_derived_one_is_refused_at_its_key(tmp_path):
    path = campaign(tmp_path, TO_TOTEM % ", hazard: caution", arm_extra=DERIVING)
    result = CliRunner().invoke(app, ["validate", "--static", str(path)])
    assert result.exit_code == 1, result.output
    [line] = [x for x in result.output.splitlines() if "hazard:" in x]
    assert line.startswith(f"{path}:4:33: hazard: caution, but the move comes within 15.")
    assert "wrist to desk: at least hazardous" in line


def test_hazard_on_a_step_that_does_not_move_and_wrong_values_are_refused(tmp_path):
    for steps, col, words in (("  - wait: {seconds: 1, hazard: caution}\n", 24,
                               "unknown key 'hazard' in wait"),
                              ("  - move: {pose: totem, hazard: risky}\n", 33, "hazard"),
                              ("  - move: {pose: totem, hazard: 2}\n", 33, "hazard")):
        path = campaign(tmp_path / str(len(steps)) / str(col), steps)
        result = CliRunner().invoke(app, ["validate", "--static", str(path)])
        assert result.exit_code == 1, result.output
        assert f"hazard.yaml:4:{col}" in result.output and words in result.output, \
            result.output


@pytest.mark.slow  # a run at virtual time with its report
def test_a_hazardous_step_asks_a_signed_confirm_before_it_starts(tmp_path):
    path = campaign(tmp_path, TO_TOTEM % "" + TO_OPSAFE % ", hazard: hazardous")
    folder = tmp_path / "run"
    result = run(path, folder, "y\nAda Lovelace\n", report=True)
    assert result.exit_code == 0, result.output
    assert "is hazardous: given in the step. Go on?" in result.output
    step = step_report(folder, 5)
    assert step["hazard"] == "hazardous" and step["hazard_speed_scale"] == 0.25
    assert step["signed_by"] == "Ada Lovelace" and len(step["inputs_sha256"]) == 64
    record = json.loads((folder / "record.json").read_text())
    assert [s["step"] for s in record["signatures"]] == [5]
    events = read_events(folder)
    signed = next(i for i, e in enumerate(events) if e["type"] == "confirm_signed")
    started = next(i for i, e in enumerate(events)
                   if e["type"] == "step_started" and e.get("step") == 5)
    assert signed < started
    html = (folder / "report.html").read_text()
    assert ('<div class="hazard" data-step="5"><strong>hazard: hazardous</strong> — given in '
            'the step; speed capped at 25 %</div>') in html
    assert "Ada Lovelace" in html


def test_a_no_at_the_hazardous_step_moves_nothing(tmp_path):
    path = campaign(tmp_path, TO_TOTEM % ", hazard: hazardous")
    folder = tmp_path / "run"
    result = run(path, folder, "n\n")
    assert result.exit_code == 130, result.output
    assert step_report(folder, 4)["status"] != "passed"
    events = read_events(folder)
    assert not any(e["type"] == "step_started" and e.get("step") == 4 for e in events)


def test_yes_refuses_a_hazardous_step_given_or_derived_before_anything_is_sent(tmp_path):
    for name, steps, arm_extra in (("given", TO_TOTEM % ", hazard: hazardous", ""),
                                   ("derived", TO_TOTEM % "", DERIVING)):
        path = campaign(tmp_path / name, steps, arm_extra=arm_extra)
        folder = tmp_path / name / "run"
        result = run(path, folder, "y\nAda\n", "--yes")
        assert result.exit_code == 2, result.output
        last = result.output.strip().splitlines()[-1]
        assert "--yes: step 4 (" in last and "hazard.yaml:4:5) is hazardous" in last, last
        assert "nothing was sent" in last
        assert not folder.exists()


def test_the_dry_run_assumes_the_signature_and_says_so(tmp_path):
    path = campaign(tmp_path, TO_TOTEM % ", hazard: hazardous")
    result = CliRunner().invoke(app, ["validate", str(path)])
    assert result.exit_code == 0, result.output
    unverified = result.output.split("not verified:")[1]
    assert "step 4: signed operator confirmation 'Step 4" in unverified


def test_a_straight_line_must_stay_within_its_class_s_cap(tmp_path):
    line = ("  - move: {pose: totem}\n  - move: {pose: opsafe}\n"
            "  - move: {position_mm: [0, 500, 300], rpy_deg: [0, 0, 90]}\n"
            "  - move_linear: {position_mm: [0, 0, -100], relative: true, frame: tool, "
            "speed_mm_s: 100%s}\n")
    fine = campaign(tmp_path / "normal", line % "")
    assert CliRunner().invoke(app, ["validate", "--static", str(fine)]).exit_code == 0
    capped = campaign(tmp_path / "hazardous", line % ", hazard: hazardous")
    result = CliRunner().invoke(app, ["validate", "--static", str(capped)])
    assert result.exit_code == 1, result.output
    assert "hazard.yaml:7:" in result.output
    assert "would have to turn at" in result.output
    assert "(the speed cap of its hazard class, 25 %)" in result.output


@pytest.mark.slow  # a session's run at virtual time
def test_the_console_s_session_asks_a_derived_hazardous_step_even_with_assume_yes(tmp_path):
    import threading

    from seqrun.arm.description import load_arm
    from seqrun.clock import VirtualClock
    from seqrun.service import ArmSession
    from seqrun.service.connection import open_connection

    path = campaign(tmp_path, TO_TOTEM % "", arm_extra=DERIVING)
    connection = open_connection(force_sim=True, clock=VirtualClock())
    session = ArmSession(load_arm(path.parent.parent / "arms" / "lwa3.yaml"), connection,
                         status_hz=0, log_root=tmp_path / "runs",
                         poses_dir=path.parent.parent / "poses")
    try:
        sub = session.subscribe(maxsize=100_000)
        asked: list = []

        def answer() -> None:
            for event in sub:
                if event.type == "confirm_requested":
                    asked.append(event)
                    session.answer(event.question_id, True, "Grace Hopper")
                if event.type == "activity_finished":
                    return

        answering = threading.Thread(target=answer, daemon=True)
        answering.start()
        result = session.run_sequence(path, assume_yes=True).wait(120)
        answering.join(10)
        assert result.ok, result.message
        assert [(e.sign, e.role) for e in asked] == [(True, "test conductor")]
        assert "is hazardous: within 15." in asked[0].text
        step = step_report(Path(result.run_dir), 4)
        assert (step["hazard"], step["signed_by"]) == ("hazardous", "Grace Hopper")
    finally:
        session.close()


def test_run_preparation_refuses_yes_before_it_opens_the_bus(tmp_path):
    """The derived class is known after the static validation, which comes before the bus
    is opened: prepare_run refuses there (a --sim run would open the simulator next)."""
    from seqrun.errors import UserInputError
    from seqrun.service.run_preparation import RunRequest, prepare_run

    path = campaign(tmp_path, TO_TOTEM % "", arm_extra=DERIVING)
    with pytest.raises(UserInputError, match=r"--yes: step 4 \(.*hazard.yaml:4:5\) is "
                                             r"hazardous \(within 15\.\d mm of wrist to desk"):
        prepare_run(RunRequest(path, sim=True, virtual_time=True, assume_yes=True))
    prepared = prepare_run(RunRequest(path, sim=True, virtual_time=True))
    try:
        assert prepared.hazards[4].hazard == "hazardous"
    finally:
        prepared.connection.close()


def test_a_run_of_several_arms_refuses_a_hazardous_step_before_anything_is_sent(tmp_path):
    root = tmp_path / "two-arms"
    shutil.copytree(ROOT / "examples" / "two-arms", root)
    path = root / "sequences" / "hold_and_approach.yaml"
    text = path.read_text()
    given = "move: {pose: totem, velocity_scale: 0.5, label: A up to Totem}"
    assert given in text
    path.write_text(text.replace(given, given.replace("label:", "hazard: hazardous, label:")))
    result = CliRunner().invoke(app, ["run", str(path), "--virtual-time", "--plain",
                                      "--log-dir", str(tmp_path / "run")], input="y\nAda\n")
    assert result.exit_code == 2, result.output
    said = "".join(result.output.splitlines())   # (a long line may wrap)
    assert "hold_and_approach.yaml:18:" in said
    assert ("is hazardous (given in the step; a signed confirm before it): not in a run of "
            "several arms yet") in said
    assert not (tmp_path / "run").exists()
