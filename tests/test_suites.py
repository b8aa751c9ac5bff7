"""Test suites (issue 40, item 1; docs/suites.md): a suite file's errors at file:line:col,
``seqrun validate SUITE`` from where each sequence leaves the arm, ``seqrun run SUITE`` on
the simulator in virtual time (setup and teardown order, on_error, loop, the suite's
junit.xml and ctrf.json), and the suite's policy itself (seqrun/service/suites.py) with
runs whose results are given."""

from __future__ import annotations

import contextlib
import json
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import xmlschema
from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers every command)
from projecttree import ROOT
from seqrun.cli.app import app
from seqrun.errors import SequenceInvalid
from seqrun.results import RunResult
from seqrun.service.suites import (SuiteRun, is_suite_file, load_suite, run_of, run_suite,
                                   suite_ctrf, suite_junit)

runner = CliRunner()
JUNIT_SCHEMA = xmlschema.XMLSchema(str(ROOT / "tests" / "data" / "junit-10.xsd"))
EXAMPLE = ROOT / "examples" / "qualification" / "suite.yaml"

START = """\
name: Start-up
steps:
  - reset
  - home
  - set_limits
"""
#: No motion: a check where the arm stands (fast in virtual time). It starts with the
#: start-up: after a failed check the Halt stays in the modules until a Reset, so a
#: sequence that goes on after one (on_error: continue) must reset them itself.
GOOD = """\
name: Good
steps:
  - include: start.yaml
  - check: {that: "tool.z_mm > 0", message: the tool is above the floor}
"""
BAD = """\
name: Bad
steps:
  - check: {that: "tool.z_mm < 0", message: the tool is below the floor}
"""
SPEEDY = """\
name: Speedy
params:
  speed: {type: float, min: 0.1, max: 1.0, default: 0.5}
  count: {type: int, default: 1}
steps:
  - move: {pose: totem, velocity_scale: "${speed}"}
"""
#: Holds only where the arm stands at Totem (tool high above the floor).
AT_TOTEM = """\
name: At Totem
steps:
  - check: {that: "tool.z_mm > 900", message: the arm stands vertical}
"""


def invoke(*args, cwd: Path):
    with contextlib.chdir(cwd):
        result = runner.invoke(app, [str(a) for a in args])
    assert "Traceback" not in result.output, result.output
    return result


@pytest.fixture
def campaign(project: Path) -> Path:
    for name, text in (("start.yaml", START), ("good.yaml", GOOD), ("bad.yaml", BAD),
                       ("speedy.yaml", SPEEDY), ("at_totem.yaml", AT_TOTEM)):
        (project / "sequences" / name).write_text(text, encoding="utf-8")
    return project


def write_suite(project: Path, body: str, name: str = "suite.yaml") -> Path:
    """The suite's path as the tests name it: relative to the campaign (their cwd)."""
    (project / name).write_text(body, encoding="utf-8")
    return Path(name)


def run_virtual(suite: Path, project: Path, folder: Path, *extra: str):
    return invoke("run", suite, "--virtual-time", "--yes", "--plain", "--no-report",
                  "--log-dir", folder, *extra, cwd=project)


def junit_suites(folder: Path) -> list[ET.Element]:
    path = folder / "junit.xml"
    assert [str(e.reason) for e in JUNIT_SCHEMA.iter_errors(str(path))] == []
    return ET.parse(path).getroot().findall("testsuite")


def ctrf(folder: Path) -> dict:
    return json.loads((folder / "ctrf.json").read_text(encoding="utf-8"))["results"]


# ------------------------------------------------------------------------ the file
def test_a_suite_is_told_from_a_sequence_by_its_top_level_key(campaign):
    suite = write_suite(campaign, "suite:\n  name: S\n  sequences: [sequences/good.yaml]\n")
    assert is_suite_file(campaign / suite)
    assert not is_suite_file(campaign / "sequences" / "good.yaml")
    assert not is_suite_file(campaign / "seqrun.toml")


def test_schema_errors_are_at_their_line_and_column(campaign):
    suite = write_suite(campaign, """\
suite:
  name: S
  sequences:
    - sequences/good.yaml
    - {fil: sequences/good.yaml}
  on_error: maybe
  loop: 0
""")
    result = invoke("validate", suite, cwd=campaign)
    assert result.exit_code == 1, result.output
    lines = result.output.splitlines()
    assert "suite.yaml:5:8: unknown key 'fil' in a suite entry (did you mean 'file'? " \
           "allowed: file, params)" in lines
    assert "suite.yaml:6:13: expected 'stop', 'continue' or 'pause', got 'maybe'" in lines
    assert "suite.yaml:7:9: must be at least 1, got 0" in lines
    assert lines[-1] == "suite.yaml: invalid suite (4 errors); nothing was sent"


def test_files_and_params_are_checked_strictly_where_the_suite_names_them(campaign):
    suite = write_suite(campaign, """\
suite:
  name: S
  sequences:
    - {file: sequences/speedy.yaml, params: {speed: "0.3", count: true, nope: 1}}
    - sequences/missing.yaml
    - {file: sequences/speedy.yaml, params: {speed: 2}}
""")
    with pytest.raises(SequenceInvalid) as caught:
        load_suite(campaign / suite)
    assert [str(e).split(": ", 1)[0].split(":", 1)[1] for e in caught.value.errors] == \
        ["4:53", "4:67", "4:73", "5:7", "6:53"]
    text = "\n".join(map(str, caught.value.errors))
    assert "params: speed: expected a finite number, got '0.3'" in text    # "0.3" is not 0.3
    assert "params: count: expected a whole number, got true" in text
    assert "sequences/speedy.yaml declares no parameter 'nope' (declared: speed, count)" in text
    assert "no sequence file sequences/missing.yaml" in text
    assert "params: speed: 2 is above the maximum 1.0" in text
    # run refuses it the same way, before anything is opened
    result = run_virtual(suite, campaign, campaign / "runs" / "x")
    assert result.exit_code == 1 and not (campaign / "runs" / "x").exists()


def test_a_campaign_of_several_arms_is_refused_in_one_line(campaign):
    (campaign / "seqrun.toml").write_text(
        '[campaign]\nname = "two"\n[arms.A]\narm = "lwa3"\n'
        '[arms.B]\narm = "lwa3"\nbase = { position_mm = [0, 900, 0] }\n', encoding="utf-8")
    suite = write_suite(campaign, "suite:\n  name: S\n  sequences: [sequences/good.yaml]\n")
    result = invoke("validate", suite, cwd=campaign)
    assert result.exit_code == 2
    assert "suites are for a campaign of one arm for now" in result.output
    assert len(result.output.strip().splitlines()) == 1


# ------------------------------------------------------------------------ validate
def test_validate_checks_each_sequence_from_where_the_one_before_leaves_the_arm(campaign):
    """at_totem.yaml holds only at Totem: valid after speedy.yaml (which goes there), not
    from Park where the suite starts."""
    chained = write_suite(campaign, """\
suite:
  name: Chained
  setup: sequences/start.yaml
  sequences:
    - {file: sequences/speedy.yaml, params: {speed: 0.8}}
    - sequences/at_totem.yaml
""")
    result = invoke("validate", chained, cwd=campaign)
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert lines[1].startswith("  setup     sequences/start.yaml: valid from park")
    assert lines[2].startswith("  #1        sequences/speedy.yaml: valid from the end of "
                               "sequences/start.yaml")
    assert lines[3].startswith("  #2        sequences/at_totem.yaml: valid from the end of "
                               "sequences/speedy.yaml")
    assert lines[-1] == "suite.yaml: valid (3 checks)"
    alone = write_suite(campaign, """\
suite:
  name: Alone
  setup: sequences/start.yaml
  sequences: [sequences/at_totem.yaml]
""", "alone.yaml")
    result = invoke("validate", alone, cwd=campaign)
    assert result.exit_code == 1, result.output
    assert "sequences/at_totem.yaml: INVALID from the end of sequences/start.yaml, dry run " \
           "FAILED" in result.output
    assert "the arm stands vertical" in result.output
    assert result.output.splitlines()[-1] == "alone.yaml: invalid (2 checks, 1 not valid)"


def test_validate_json_gives_each_entry(campaign):
    suite = write_suite(campaign, """\
suite:
  name: S
  setup: sequences/start.yaml
  sequences: [sequences/good.yaml, sequences/bad.yaml]
  loop: 2
""")
    result = invoke("validate", "--json", suite, cwd=campaign)
    assert result.exit_code == 1
    data = json.loads(result.stdout)
    assert data["valid"] is False
    assert [(e["role"], e["file"], e["valid"]) for e in data["entries"]] == [
        ("setup", "sequences/start.yaml", True), ("sequence", "sequences/good.yaml", True),
        ("sequence", "sequences/bad.yaml", False), ("sequence", "sequences/good.yaml", True)]
    assert any("loop" in line for line in data["not_checked"])


# ------------------------------------------------------------ the policy, runs given
def _result(code: int, cause: str | None = None, confirmed: bool = True) -> RunResult:
    fault = None if cause is None else {"cause": cause, "halt_sent": True,
                                        "halt_confirmed": confirmed}
    status = {0: "passed", 130: "aborted"}.get(code, "failed")
    return RunResult(status, code, "done" if code == 0 else "it failed", [], 0.0, 1.5, fault)


def _policy_suite(tmp_path: Path, on_error: str, loop: int = 1):
    project = tmp_path / "p"
    (project / "sequences").mkdir(parents=True)
    for name in ("s.yaml", "a.yaml", "b.yaml", "t.yaml"):
        (project / "sequences" / name).write_text(GOOD, encoding="utf-8")
    path = project / "suite.yaml"
    path.write_text(f"suite:\n  name: P\n  setup: sequences/s.yaml\n"
                    f"  sequences: [sequences/a.yaml, sequences/b.yaml]\n"
                    f"  teardown: sequences/t.yaml\n  on_error: {on_error}\n  loop: {loop}\n",
                    encoding="utf-8")
    return load_suite(path)


def _play(suite, results: dict[str, RunResult], ask=None):
    """Run the policy with the given results (by file stem; passed otherwise)."""
    order: list[str] = []

    def one(item, folder: Path) -> SuiteRun:
        order.append(f"{item.path.stem}{item.loop or ''}")
        return run_of(item, results.get(item.path.stem, _result(0)), folder, 0.0)

    lines: list[str] = []
    outcome = run_suite(suite, Path("/nowhere"), one, ask_continue=ask,
                        told=lambda text, _o: lines.append(text))
    return order, outcome, lines


def test_setup_sequences_loop_teardown_in_order(tmp_path):
    order, outcome, lines = _play(_policy_suite(tmp_path, "stop", loop=3), {})
    assert order == ["s", "a1", "b1", "a2", "b2", "a3", "b3", "t"]
    assert (outcome.passed, outcome.failed, outcome.exit_code) == (8, 0, 0)
    assert "suite 2/8 loop 1/3: sequences/a.yaml" in lines
    assert lines[-1].endswith("passed 8, failed 0")


@pytest.mark.parametrize("on_error, expected", [
    ("stop", ["s", "a1", "t"]),
    ("continue", ["s", "a1", "b1", "a2", "b2", "t"])])
def test_a_failed_check_stops_or_continues_and_the_teardown_runs(tmp_path, on_error,
                                                                   expected):
    order, outcome, _ = _play(_policy_suite(tmp_path, on_error, loop=2),
                              {"a": _result(3, "checkpoint")})
    assert order == expected
    assert outcome.exit_code == 3 and outcome.verdict == "failed"
    not_run = [r.item.path.stem for r in outcome.runs if r.status == "not run"]
    assert not_run == ([] if on_error == "continue" else ["b", "a", "b"])


@pytest.mark.parametrize("result", [_result(3, "tow_error"), _result(3, "checkpoint", False),
                                    _result(130)])
def test_after_a_fault_or_an_abort_nothing_moves_the_arm_not_even_the_teardown(tmp_path,
                                                                                result):
    order, outcome, lines = _play(_policy_suite(tmp_path, "continue"), {"a": result})
    assert order == ["s", "a1"]
    assert [r.status for r in outcome.runs][-2:] == ["not run", "not run"]
    assert "no teardown" in outcome.stopped
    assert outcome.exit_code == result.exit_code


def test_a_failed_setup_runs_no_sequence_but_the_teardown(tmp_path):
    order, outcome, _ = _play(_policy_suite(tmp_path, "continue"),
                              {"s": _result(3, "checkpoint")})
    assert order == ["s", "t"]
    assert "the setup sequences/s.yaml failed" in outcome.stopped


@pytest.mark.parametrize("answer, expected", [(True, ["s", "a1", "b1", "t"]),
                                              (False, ["s", "a1", "t"])])
def test_pause_asks_the_operator(tmp_path, answer, expected):
    asked: list[str] = []

    def ask(run: SuiteRun) -> bool:
        asked.append(run.item.shown)
        return answer

    order, _, _ = _play(_policy_suite(tmp_path, "pause"), {"a": _result(3, "checkpoint")},
                        ask=ask)
    assert order == expected and asked == ["sequences/a.yaml"]


def test_the_reports_count_what_ran_and_what_did_not(tmp_path):
    _, outcome, _ = _play(_policy_suite(tmp_path, "stop"), {"a": _result(3, "checkpoint")})
    (tmp_path / "out").mkdir()
    junit = tmp_path / "out" / "junit.xml"
    junit.write_text(suite_junit(outcome), encoding="utf-8")
    suites = junit_suites(tmp_path / "out")
    assert [s.get("name") for s in suites] == [
        "setup: sequences/s.yaml", "loop 1 #1: sequences/a.yaml",
        "loop 1 #2: sequences/b.yaml", "teardown: sequences/t.yaml"]
    assert [s.get("skipped") for s in suites] == ["0", "0", "1", "0"]
    report = json.loads(suite_ctrf(outcome))["results"]
    assert report["tool"]["name"] == "seqrun"
    summary = report["summary"]
    assert {k: summary[k] for k in ("tests", "passed", "failed", "skipped", "pending",
                                    "other")} == \
        {"tests": 4, "passed": 2, "failed": 1, "skipped": 1, "pending": 0, "other": 0}
    assert [(t["name"], t["status"], t["duration"]) for t in report["tests"]] == [
        ("setup: sequences/s.yaml", "passed", 1500),
        ("loop 1 #1: sequences/a.yaml", "failed", 1500),
        ("loop 1 #2: sequences/b.yaml", "skipped", 0),
        ("teardown: sequences/t.yaml", "passed", 1500)]
    assert summary["start"] <= summary["stop"]


# ------------------------------------------------------------------ run, simulator
@pytest.mark.parametrize("on_error", ["stop", "continue"])
def test_run_a_suite_on_the_simulator(campaign, tmp_path, on_error):
    suite = write_suite(campaign, f"""\
suite:
  name: Run
  setup: sequences/start.yaml
  sequences: [sequences/good.yaml, sequences/bad.yaml, sequences/good.yaml]
  teardown: sequences/start.yaml
  on_error: {on_error}
  loop: 2
""")
    folder = tmp_path / "suite"
    result = run_virtual(suite, campaign, folder)
    assert result.exit_code == 3, result.output
    out = result.output
    assert out.index("suite 1/8 setup: sequences/start.yaml") < \
        out.index("suite 2/8 loop 1/2: sequences/good.yaml") < \
        out.index("suite 3/8 loop 1/2: sequences/bad.yaml") < \
        out.index("suite 8/8 teardown: sequences/start.yaml")
    ran = 8 if on_error == "continue" else 4
    assert f"SUITE FAILED (exit 3): Run: {ran - 2 if on_error == 'continue' else 3} passed, " \
           f"{2 if on_error == 'continue' else 1} failed, {8 - ran} not run" in out
    folders = sorted(p.name for p in folder.iterdir() if p.is_dir())
    assert len(folders) == ran and folders[0] == "01-start" and folders[-1] == "08-start"
    for name in folders:   # each run a full run folder of its own
        report = json.loads((folder / name / "report.json").read_text(encoding="utf-8"))
        assert report["status"] == ("failed" if name.endswith("bad") else "passed")
    suites = junit_suites(folder)
    assert len(suites) == 8
    assert sum(int(s.get("failures")) for s in suites) == (2 if on_error == "continue" else 1)
    assert sum(int(s.get("skipped") or 0) for s in suites) == 8 - ran
    summary = ctrf(folder)["summary"]
    assert (summary["tests"], summary["passed"], summary["failed"], summary["skipped"]) == \
        (8, ran - (2 if on_error == "continue" else 1), 2 if on_error == "continue" else 1,
         8 - ran)


@pytest.mark.slow
def test_a_fault_stops_the_suite_without_its_teardown(campaign, tmp_path):
    suite = write_suite(campaign, """\
suite:
  name: Fault
  setup: sequences/start.yaml
  sequences: [sequences/speedy.yaml, sequences/good.yaml]
  teardown: sequences/start.yaml
  on_error: continue
""")
    result = invoke("run", suite, "--virtual-time", "--yes", "--plain", "--no-report",
                    "--sim-fault", "4:tow_error@1", cwd=campaign)
    assert result.exit_code == 3, result.output
    assert "nothing moves the arm by itself now (no teardown)" in result.output
    (folder,) = (campaign / "runs").glob("*-suite-Fault")   # the campaign's runs folder
    assert sorted(p.name for p in folder.iterdir() if p.is_dir()) == ["01-start",
                                                                      "02-speedy"]
    assert [t["status"] for t in ctrf(folder)["tests"]] == ["passed", "failed", "skipped",
                                                           "skipped"]
    # seqrun runs lists the suite's runs among the campaign's
    listed = json.loads(invoke("runs", "--json", cwd=campaign).stdout)
    assert [(Path(r["folder"]).name, r["result"]) for r in listed] == [
        ("01-start", "passed"), ("02-speedy", "failed")]


@pytest.mark.slow
def test_the_qualification_example_validates_and_runs(tmp_path):
    result = invoke("validate", EXAMPLE, cwd=ROOT)
    assert result.exit_code == 0, result.output
    assert result.output.splitlines()[-1].endswith("suite.yaml: valid (5 checks)")
    folder_check = invoke("validate", EXAMPLE.parent, cwd=ROOT)   # the campaign folder
    assert folder_check.exit_code == 0, folder_check.output
    assert folder_check.output.splitlines()[-1] == "1 file: all valid"
    # its hazardous step (out_to_opsafe.yaml) needs a signature: --yes refuses the suite
    refused = run_virtual(EXAMPLE, ROOT, tmp_path / "yes")
    assert refused.exit_code == 2, refused.output
    assert "out_to_opsafe.yaml:8:5) is hazardous" in refused.output
    assert not (tmp_path / "yes").exists()
    folder = tmp_path / "q"
    with contextlib.chdir(ROOT):   # the person at the run signs for it
        result = runner.invoke(app, ["run", str(EXAMPLE), "--virtual-time", "--plain",
                                     "--no-report", "--log-dir", str(folder)],
                               input="y\nAda Lovelace\n")
    assert result.exit_code == 0, result.output
    assert "SUITE PASSED (exit 0): Qualification: 5 passed, 0 failed, 0 not run" in \
        result.output
    [signed] = [r for r in folder.glob("*/record.json")
                if "signatures" in json.loads(r.read_text())]
    assert json.loads(signed.read_text())["signatures"][0]["signed_by"] == "Ada Lovelace"
    assert [s.get("name") for s in junit_suites(folder)] == [
        "setup: sequences/startup.yaml", "loop 1 #1: sequences/up_to_totem.yaml",
        "loop 1 #2: sequences/out_to_opsafe.yaml", "loop 1 #3: sequences/back_to_totem.yaml",
        "teardown: sequences/park.yaml"]
    assert ctrf(folder)["summary"]["passed"] == 5


@pytest.mark.parametrize("answer, ran", [("", 2), ("y\n", 3)])
def test_pause_asks_the_person_at_the_terminal_and_yes_does_not_answer(campaign, tmp_path,
                                                                        answer, ran):
    """--yes answers confirm steps, never the pause: with no one to answer (end of input)
    the suite stops; a person's yes goes on."""
    suite = write_suite(campaign, """\
suite:
  name: Pause
  sequences: [sequences/good.yaml, sequences/bad.yaml, sequences/good.yaml]
  on_error: pause
""")
    folder = tmp_path / "suite"
    with contextlib.chdir(campaign):
        result = runner.invoke(app, ["run", str(suite), "--virtual-time", "--yes", "--plain",
                                     "--no-report", "--log-dir", str(folder)], input=answer)
    assert result.exit_code == 3, result.output
    assert "sequences/bad.yaml failed (check failed: tool.z_mm < 0 (the tool is below the " \
           "floor)). Continue the suite with the next sequence?" in result.output
    assert len([p for p in folder.iterdir() if p.is_dir()]) == ran


def test_static_validation_chains_the_planned_ends(campaign):
    suite = write_suite(campaign, """\
suite:
  name: Static
  setup: sequences/start.yaml
  sequences: [sequences/speedy.yaml, sequences/speedy.yaml]
""")
    result = invoke("validate", "--static", suite, cwd=campaign)
    assert result.exit_code == 0, result.output
    assert "  #2        sequences/speedy.yaml: valid from the planned end of " \
           "sequences/speedy.yaml" in result.output
    assert "not checked: --static: no dry run" in result.output


def test_a_campaign_folder_checks_its_suite_and_its_sequences_in_the_suites_order(project):
    """at_totem.yaml is not valid alone (from Park) but is in its suite's order: the
    campaign's table has the suite's row, not the sequences it checked."""
    for name, text in (("start.yaml", START), ("speedy.yaml", SPEEDY),
                       ("at_totem.yaml", AT_TOTEM)):
        (project / "sequences" / name).write_text(text, encoding="utf-8")
    write_suite(project, """\
suite:
  name: Campaign
  setup: sequences/start.yaml
  sequences: [{file: sequences/speedy.yaml, params: {speed: 0.8}}, sequences/at_totem.yaml]
""")
    result = invoke("validate", ".", cwd=project)
    assert result.exit_code == 0, result.output
    rows = [line.split()[:2] for line in result.output.splitlines()
            if line.startswith(("suite.yaml ", "sequences/")) and "note:" not in line]
    assert rows == [["suite.yaml", "valid"], ["sequences/startup.yaml", "valid"]], result.output
    assert "its 3 sequence files are checked in its order" in result.output
    alone = invoke("validate", "sequences/at_totem.yaml", cwd=project)
    assert alone.exit_code == 1
