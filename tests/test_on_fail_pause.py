"""Issue 39, item 6 (the last part): ``on_fail: pause`` hands the operator Retry / Skip /
Abort after a step's failure that may be retried (its own retries spent), at the terminal
and in the console, each answer an ``operator_choice`` event and a line of the step's
report. A fault is never offered; ``--yes`` never answers it; a dry run never pauses."""

from __future__ import annotations

import contextlib
import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers every command)
from runfolder import RunFolder
from seqrun.cli.app import app

runner = CliRunner()

HEAD = """\
name: Pause
steps:
  - reset
  - home
  - set_limits
"""  # the steps below start on line 6

#: Fails its first attempt (0.2 s, from a start well before 0.5 s), passes on a retry.
LATE = ("  - wait_until: {until: 'sequence_time_s > 0.5', timeout_s: 0.3, on_fail: pause, "
        "label: Late}\n")
#: Never holds.
NEVER = "  - check: {that: 'tool.z_mm > 5000', on_fail: pause, label: Never}\n"
AFTER = "  - move: {joints: {j1: 5}, label: After}\n"


def write(project: Path, steps: str) -> Path:
    path = project / "sequences" / "p.yaml"
    path.write_text(HEAD + steps, encoding="utf-8")
    return path


def invoke(*args, cwd: Path, stdin: str = ""):
    with contextlib.chdir(cwd):
        result = runner.invoke(app, [str(a) for a in args], input=stdin)
    assert "Traceback" not in result.output, result.output
    return result


def run_virtual(path: Path, project: Path, folder: Path, stdin: str, *extra: str):
    return invoke("run", path, "--virtual-time", "--plain", "--no-report", "--log-dir",
                  folder, *extra, cwd=project, stdin=stdin)


def report(folder: Path) -> dict:
    return json.loads((folder / "report.json").read_text(encoding="utf-8"))


def choices(folder: Path) -> list[tuple[int, str, str]]:
    return [(e["step"], e["choice"], e["by"]) for e in RunFolder(folder).events()
            if e["type"] == "operator_choice"]


def test_retry_runs_the_step_again_and_the_run_passes(project, tmp_path):
    path = write(project, LATE)
    folder = tmp_path / "run"
    result = run_virtual(path, project, folder, "r\n")
    assert result.exit_code == 0, result.output
    assert result.output.count("Retry, skip or abort? [r/s/a]") == 1
    assert choices(folder) == [(4, "retry", "terminal")]
    step = report(folder)["steps"][3]
    assert step["status"] == "passed"
    assert [c["choice"] for c in step["operator_choices"]] == ["retry"]
    assert "did not hold within 0.3 s" in step["operator_choices"][0]["after"]


def test_skip_leaves_the_step_failed_and_the_run_goes_on_and_passes(project, tmp_path):
    path = write(project, NEVER + AFTER)
    folder = tmp_path / "run"
    result = invoke("run", path, "--virtual-time", "--plain", "--log-dir", folder,
                    cwd=project, stdin="x\nskip\n")   # asked again after "x"
    assert result.exit_code == 0, result.output
    assert "Answer one of: r (retry), s (skip), a (abort)." in result.output
    assert choices(folder) == [(4, "skip", "terminal")]
    data = report(folder)
    never, after = data["steps"][3], data["steps"][4]
    assert never["status"] == "failed" and never["skipped_by"] == "operator"
    assert never["error"] == never["operator_choices"][0]["after"]
    assert after["status"] == "passed"
    html = (folder / "report.html").read_text(encoding="utf-8")
    assert ('<div class="operator-choice" data-step="4"><strong>the operator chose skip'
            '</strong> (terminal) after: check failed: tool.z_mm &gt; 5000</div>') in html
    events = RunFolder(folder).events()
    [recheck] = [e for e in events if e["type"] == "skip_recheck"]
    assert (recheck["first_step"], recheck["steps"], recheck["errors"]) == (5, 1, [])
    # the rest was checked before anything moved again
    order = [e["type"] for e in events]
    assert order.index("skip_recheck") < max(i for i, t in enumerate(order)
                                             if t == "step_started")


def test_abort_is_an_operator_abort_and_nothing_moves_after(project, tmp_path):
    path = write(project, NEVER + AFTER)
    folder = tmp_path / "run"
    result = run_virtual(path, project, folder, "a\n")
    assert result.exit_code == 130, result.output
    assert choices(folder) == [(4, "abort", "terminal")]
    data = report(folder)
    assert [s["status"] for s in data["steps"][3:]] == ["aborted", "pending"]
    assert data["steps"][3]["operator_choices"][0]["choice"] == "abort"
    events = RunFolder(folder).events()
    chosen = next(i for i, e in enumerate(events) if e["type"] == "operator_choice")
    later = [e["type"] for e in events[chosen:]]
    assert "step_started" not in later and "fault" not in later
    assert not any(t.startswith("move") or t == "plan" for t in later), later


def test_no_answer_at_the_end_of_input_is_an_abort(project, tmp_path):
    path = write(project, NEVER)
    folder = tmp_path / "run"
    result = run_virtual(path, project, folder, "")
    assert result.exit_code == 130, result.output
    assert choices(folder) == [(4, "abort", "nobody answered")]


def test_a_module_fault_is_never_offered(project, tmp_path):
    path = write(project, "  - wait_until: {until: 'sequence_time_s > 100', timeout_s: 2, "
                          "on_fail: pause}\n")
    folder = tmp_path / "run"
    result = run_virtual(path, project, folder, "r\nr\n", "--sim-fault", "4:tow_error@0.5")
    assert result.exit_code == 3, result.output
    assert "Retry, skip or abort?" not in result.output
    data = report(folder)
    assert data["fault"]["cause"] == "tow_error" and data["fault"]["halt_confirmed"] is True
    assert choices(folder) == []


def test_yes_never_answers_it_and_nothing_is_sent(project, tmp_path):
    path = write(project, NEVER)
    folder = tmp_path / "run"
    result = run_virtual(path, project, folder, "s\n", "--yes")
    assert result.exit_code == 2, result.output
    [line] = result.output.strip().splitlines()[-1:]
    assert "--yes" in line and "nothing was sent" in line
    assert "p.yaml:6:5" in line and "on_fail: pause" in line
    assert not folder.exists()


def test_the_dry_run_never_pauses_and_lists_the_choice_as_not_verified(project):
    path = write(project, LATE.replace("0.5", "0.01"))
    result = invoke("validate", "--json", path, cwd=project)
    dry = json.loads(result.stdout)["dry_run"]
    assert dry["passed"] is True, dry
    assert any("on_fail: pause: the operator's choice (retry, skip, abort) is not "
               "verified" in item and item.startswith("step 4") for item in dry["not_verified"])
    # a failure in the dry run fails it as without on_fail
    path = write(project, NEVER)
    result = invoke("validate", "--json", path, cwd=project)
    assert json.loads(result.stdout)["dry_run"]["passed"] is False


@pytest.mark.parametrize("steps, where, message", [
    ("  - wait: {seconds: 1, on_fail: pause}\n", "6:24",
     "on_fail: pause: a wait step does not fail in a way the operator may retry"),
    ("  - check: {that: 'tool.z_mm > 0', on_fail: stop}\n", "6:45", "'fail' or 'pause'"),
    ("  - block:\n      steps:\n        - check: {that: 'tool.z_mm > 0', on_fail: pause}\n",
     "8:42", "on_fail: pause: a step in a block: its rescue decides"),
    ("  - include: {file: startup.yaml, on_fail: pause}\n", "6:14", "on_fail"),
])
def test_on_fail_is_refused_where_it_cannot_hold(project, steps, where, message):
    path = write(project, steps)
    result = invoke("validate", path, cwd=project)
    assert result.exit_code == 1, result.output
    assert f"p.yaml:{where}:" in result.output and message in result.output, result.output


def test_a_sequence_without_on_fail_ends_at_the_failure_as_before(project, tmp_path):
    path = write(project, NEVER.replace(", on_fail: pause", "") + AFTER)
    folder = tmp_path / "run"
    result = run_virtual(path, project, folder, "", "--yes")
    assert result.exit_code == 3, result.output
    assert choices(folder) == [] and "Retry, skip or abort?" not in result.output


# --------------------------------------------------------------------------- the console
def test_the_console_offers_the_choices_and_only_the_control_holder_answers(tmp_path):
    from consolekit import CONTROL, LIVE, LOCAL, console_setup
    from fastapi.testclient import TestClient

    setup = console_setup(tmp_path)
    (setup.folder / "sequences" / "pause.yaml").write_text(
        "name: Pause\nsteps:\n" + NEVER + "  - wait: {seconds: 0.1, label: After}\n")

    def next_event(ws, type_: str, pinging=()) -> dict:
        while True:
            for page in pinging:
                page.send_json({"op": "ping"})
            message = ws.receive_json()
            if message["type"] == "event" and message["event"]["type"] == type_:
                return message["event"]

    try:
        with TestClient(setup.app(), base_url=LOCAL) as client, \
                client.websocket_connect(LIVE) as tab_a, \
                client.websocket_connect(LIVE) as tab_b:
            a, b = tab_a.receive_json(), tab_b.receive_json()
            as_a, as_b = {CONTROL: a["token"]}, {CONTROL: b["client"]}
            r = client.post("/api/v1/run", json={"sequence": "pause.yaml"}, headers=as_a)
            assert r.status_code == 200, r.text
            question = next_event(tab_b, "confirm_requested", pinging=(tab_a,))
            assert question["choices"] == ["retry", "skip", "abort"]
            assert "Retry, skip or abort?" in question["text"]
            skip = {"question_id": question["question_id"], "yes": True, "choice": "skip"}
            r = client.post("/api/v1/answer", json=skip, headers=as_b)
            assert r.status_code == 409 and "holds control" in r.json()["error"]
            r = client.post("/api/v1/answer", json={**skip, "choice": "later"}, headers=as_a)
            assert r.status_code == 409 and "choose one of retry, skip, abort" in r.text
            assert client.post("/api/v1/answer", json=skip, headers=as_a).status_code == 200
            chosen = next_event(tab_a, "operator_choice", pinging=(tab_a,))
            assert (chosen["choice"], chosen["by"], chosen["step"]) == ("skip", "console", 1)
            finished = next_event(tab_a, "run_finished", pinging=(tab_a,))
            assert finished["status"] == "passed", finished
    finally:
        setup.close()
    [folder] = [p for p in setup.runs.rglob("report.json")]
    steps = json.loads(folder.read_text())["steps"]
    assert [s["status"] for s in steps] == ["failed", "passed"]
    assert steps[0]["skipped_by"] == "operator"
    assert steps[0]["operator_choices"][0]["by"] == "console"


def test_a_campaign_of_several_arms_refuses_it_at_its_line(tmp_path):
    import shutil

    from projecttree import ROOT

    campaign = tmp_path / "two"
    shutil.copytree(ROOT / "examples" / "two-arms", campaign,
                    ignore=shutil.ignore_patterns("runs"))
    path = campaign / "sequences" / "hold_and_approach.yaml"
    text = path.read_text(encoding="utf-8")
    move = "          - move: {pose: totem, velocity_scale: 0.5, label: A up to Totem}\n"
    assert move in text
    path.write_text(text.replace(move, move + "          - check: {that: 'tool.z_mm > 0', "
                                              "on_fail: pause}\n", 1), encoding="utf-8")
    result = invoke("validate", "--static", path, cwd=campaign)
    assert result.exit_code == 1, result.output
    assert ("sequences/hold_and_approach.yaml:19:44: on_fail: pause: a campaign of several "
            "arms") in result.output, result.output


def test_a_choice_answers_only_a_question_that_offers_it():
    import threading

    from consolekit import wait_for
    from seqrun.errors import Refused
    from seqrun.service.questions import Questions

    published: list[tuple[str, dict]] = []
    questions = Questions(lambda type_, **fields: published.append((type_, fields)),
                          lambda: False)
    got: dict[str, object] = {}
    asking = [threading.Thread(target=lambda: got.setdefault(
                  "choice", questions.ask_choice("Retry?", ("retry", "skip", "abort")))),
              threading.Thread(target=lambda: got.setdefault("yes", questions.ask("Go?")))]
    for thread in asking:
        thread.start()
    wait_for(lambda: len(published) == 2)
    asked = {f["text"]: f for t, f in published if t == "confirm_requested"}
    choose, plain = asked["Retry?"]["question_id"], asked["Go?"]["question_id"]
    assert asked["Retry?"]["choices"] == ["retry", "skip", "abort"]
    assert "choices" not in asked["Go?"]
    for bad in (None, "later", "Retry"):
        with pytest.raises(Refused, match="choose one of retry, skip, abort"):
            questions.answer(choose, True, choice=bad)
    with pytest.raises(Refused, match="offers no choices"):
        questions.answer(plain, True, choice="skip")
    questions.answer(choose, True, choice="retry")
    questions.answer(plain, True)
    for thread in asking:
        thread.join(5)
    assert got == {"choice": "retry", "yes": True}
    answered = [f for t, f in published if t == "confirm_answered"]
    assert [(f["yes"], f.get("choice")) for f in answered] == [(True, "retry"), (True, None)]
    # a no (or the withdrawal) chooses nothing: the run takes it as an abort
    thread = threading.Thread(target=lambda: got.update(
        late=questions.ask_choice("Again?", ("retry", "skip", "abort"))))
    thread.start()
    wait_for(lambda: questions.pending())
    questions.withdraw()
    thread.join(5)
    assert got["late"] is None


def test_own_retries_come_first_and_a_failed_retry_asks_again(project, tmp_path):
    path = write(project, NEVER.replace("on_fail: pause", "on_fail: pause, retry: {times: 2}"))
    folder = tmp_path / "run"
    result = run_virtual(path, project, folder, "r\nr\na\n")
    assert result.exit_code == 130, result.output
    assert [c[1] for c in choices(folder)] == ["retry", "retry", "abort"]
    events = RunFolder(folder).events()
    kinds = [e["type"] for e in events if e["type"] in ("step_retry", "operator_choice")]
    assert kinds == ["step_retry", "step_retry"] + ["operator_choice"] * 3
    assert len(report(folder)["steps"][3]["retries"]) == 2
