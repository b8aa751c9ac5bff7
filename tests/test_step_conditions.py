"""Issue 39 (items 5 and 6, in part): ``if`` / ``skip_if``, ``repeat`` and ``retry`` on a
step, through ``seqrun validate`` (the dry run) and ``seqrun run --virtual-time`` alike.

A skipped step says which condition skipped it and the value it had; iterations and
retries are events and lines; only a failed measurement is retried, never a fault; and the
dry run lists every branch it did not take under "not verified"."""

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
name: Flow
steps:
  - reset
  - home
  - set_limits
"""  # the steps below start on line 6


def write(project: Path, steps: str, name: str = "f.yaml") -> Path:
    path = project / "sequences" / name
    path.write_text(HEAD + steps, encoding="utf-8")
    return path


def invoke(*args, cwd: Path):
    with contextlib.chdir(cwd):
        return runner.invoke(app, [str(a) for a in args])


def validate_json(path: Path, project: Path, *extra: str) -> dict:
    result = invoke("validate", "--json", path, *extra, cwd=project)
    assert "Traceback" not in result.output
    return json.loads(result.stdout)


def run_virtual(path: Path, project: Path, folder: Path, *extra: str):
    result = invoke("run", path, "--virtual-time", "--yes", "--plain", "--no-report",
                    "--log-dir", folder, *extra, cwd=project)
    assert "Traceback" not in result.output
    return result


def report(folder: Path) -> dict:
    return json.loads((folder / "report.json").read_text(encoding="utf-8"))


# --------------------------------------------------------------------------- if / skip_if
CONDITIONS = """\
  - wait: {seconds: 0.1, skip_if: "pos_deg[2] < 0"}
  - wait: {seconds: 0.1, if: "pos_deg[2] > 0"}
  - wait: {seconds: 0.1, if: "pos_deg[2] < 0"}
"""


def test_skip_if_and_a_false_if_skip_the_step_in_the_dry_run_and_the_run(project, tmp_path):
    path = write(project, CONDITIONS)
    dry = validate_json(path, project)["dry_run"]
    assert dry["passed"] is True, dry
    folder = tmp_path / "run"
    result = run_virtual(path, project, folder)
    assert result.exit_code == 0, result.output
    ran = report(folder)["steps"]
    for steps in (dry["steps"], ran):
        skipped, not_taken, taken = steps[3], steps[4], steps[5]
        # Park: j2 at -90 degrees
        assert skipped["status"] == "skipped" and skipped["skipped_by"] == "skip_if"
        assert skipped["condition"] == "pos_deg[2] < 0" and skipped["value"] is True
        assert skipped["values"]["pos_deg[2]"] == pytest.approx(-90, abs=0.01)
        assert not_taken["status"] == "skipped" and not_taken["skipped_by"] == "if"
        assert not_taken["value"] is False
        assert taken["status"] == "passed" and taken["waited_s"] == pytest.approx(0.1)
    assert "      skipped: skip_if 'pos_deg[2] < 0' was true" in result.stdout
    assert "      skipped: if 'pos_deg[2] > 0' was false" in result.stdout
    events = [e for e in RunFolder(folder).events() if e["type"] == "step_skipped"]
    assert [(e["step"], e["key"], e["value"]) for e in events] == [
        (4, "skip_if", True), (5, "if", False)]
    # a skipped step never started
    started = {e["step"] for e in RunFolder(folder).events() if e["type"] == "step_started"}
    assert 4 not in started and 5 not in started and 6 in started


@pytest.mark.slow  # draws report.html
def test_the_report_shows_the_skipped_step_with_its_condition(project, tmp_path):
    path = write(project, '  - wait: {seconds: 0.1, skip_if: "pos_deg[2] < 0"}\n')
    folder = tmp_path / "run"
    with contextlib.chdir(project):
        result = runner.invoke(app, ["run", str(path), "--virtual-time", "--yes", "--plain",
                                     "--log-dir", str(folder)])
    assert result.exit_code == 0, result.output
    html = (folder / "report.html").read_text(encoding="utf-8")
    row = html[html.index('id="step-4"'):]
    row = row[:row.index("</tr>", row.index("</tr>") + 1)]
    assert "<td>skipped</td>" in row
    assert "skipped_by: skip_if; condition: pos_deg[2] &lt; 0; value: yes" in row


def test_the_dry_run_lists_each_branch_it_did_not_take(project):
    path = write(project, CONDITIONS + """\
  - check: {that: "tool.z_mm > 40", retry: {times: 2}}
""")
    result = invoke("validate", path, cwd=project)
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    heading = lines.index("  not verified:")
    listed = lines[heading + 1:]
    where = "sequences/f.yaml"
    assert (f"    - step 4 ({where}:6:5): skip_if 'pos_deg[2] < 0' was never false, so "
            "running the step was not exercised") in listed
    assert (f"    - step 5 ({where}:7:5): if 'pos_deg[2] > 0' was never true, so running "
            "the step was not exercised") in listed
    assert (f"    - step 6 ({where}:8:5): if 'pos_deg[2] < 0' was never false, so skipping "
            "the step was not exercised") in listed
    assert (f"    - step 7 ({where}:9:5): its retry was never exercised (the step never "
            "failed in a way that may be retried)") in listed
    unverified = validate_json(path, project)["dry_run"]["not_verified"]
    assert sum(1 for item in unverified if item.startswith("step ")) == 4, unverified


def test_a_branch_taken_at_a_parameters_range_end_is_not_listed(project):
    """validate dry-runs each numeric parameter at its min and max too: a branch one of
    those runs took was run; a branch no run took stays listed."""
    path = project / "sequences" / "r.yaml"
    path.write_text(HEAD.replace("steps:\n", "params:\n  n: {type: int, min: 1, max: 4, "
                                             "default: 2}\nsteps:\n") + """\
  - wait: {seconds: 0.1, if: "params.n > 3"}
  - wait: {seconds: 0.1, if: "params.n > 9"}
""", encoding="utf-8")
    result = invoke("validate", path, cwd=project)
    assert result.exit_code == 0, result.output
    listed = [line for line in result.stdout.splitlines() if line.startswith("    - step")]
    # n = 4 (its max) ran step 4; nothing ran step 5
    assert listed == ["    - step 5 (sequences/r.yaml:9:5): if 'params.n > 9' was never "
                      "true, so running the step was not exercised"], result.stdout


def test_a_file_without_flow_keys_lists_no_branch(project):
    path = write(project, "  - wait: 0.1\n  - check: tool.z_mm > 40\n")
    unverified = validate_json(path, project)["dry_run"]["not_verified"]
    assert not any(item.startswith("step ") for item in unverified), unverified


# --------------------------------------------------------------------------- repeat
def test_repeat_count_runs_the_step_n_times_and_says_each_iteration(project, tmp_path):
    path = write(project, "  - wait: {seconds: 0.2, repeat: {count: 3}}\n")
    dry = validate_json(path, project)["dry_run"]
    folder = tmp_path / "run"
    result = run_virtual(path, project, folder)
    assert result.exit_code == 0, result.output
    for step in (dry["steps"][3], report(folder)["steps"][3]):
        assert step["status"] == "passed" and step["iterations"] == 3
        assert step["duration_s"] == pytest.approx(0.6, abs=0.02)
    for i in (1, 2, 3):
        assert f"[4/4] wait 0.2 s{' (sequences/f.yaml:6:5)' if i == 1 else ''} ({i}/3)" \
            in result.stdout, result.stdout
    iterations = [e["iteration"] for e in RunFolder(folder).events()
                  if e["type"] == "step_iteration"]
    assert iterations == [2, 3]


def test_repeat_while_stops_when_the_condition_no_longer_holds(project, tmp_path):
    path = write(project, "  - wait: {seconds: 0.25, repeat: {while: 'sequence_time_s < 1', "
                          "max: 20}}\n")
    dry = validate_json(path, project)["dry_run"]
    folder = tmp_path / "run"
    result = run_virtual(path, project, folder)
    assert result.exit_code == 0, result.output
    dry_step, run_step = dry["steps"][3], report(folder)["steps"][3]
    assert dry_step["iterations"] == run_step["iterations"]
    assert 2 <= run_step["iterations"] <= 5
    assert "[4/4] wait 0.25 s (sequences/f.yaml:6:5) (1, at most 20)" in result.stdout
    assert f"[4/4] wait 0.25 s ({run_step['iterations']}, at most 20)" in result.stdout


def test_repeat_while_past_its_max_is_a_fault(project, tmp_path):
    path = write(project, "  - wait: {seconds: 0.1, repeat: {while: 'tool.z_mm > 0', "
                          "max: 3}}\n")
    folder = tmp_path / "run"
    result = run_virtual(path, project, folder)
    assert result.exit_code == 3, result.output
    assert report(folder)["message"].startswith(
        "repeat: 'tool.z_mm > 0' still held after max 3 iterations")


# --------------------------------------------------------------------------- retry
RETRIED = ("  - wait_until: {until: 'sequence_time_s > 0.5', timeout_s: 0.2, "
           "retry: {times: 3, delay_s: 0.2}}\n")


def test_a_timed_out_wait_until_succeeds_on_a_retry(project, tmp_path):
    path = write(project, RETRIED)
    dry = validate_json(path, project)["dry_run"]
    assert dry["passed"] is True, dry
    folder = tmp_path / "run"
    result = run_virtual(path, project, folder)
    assert result.exit_code == 0, result.output
    for step in (dry["steps"][3], report(folder)["steps"][3]):
        assert step["status"] == "passed"
        assert [r["attempt"] for r in step["retries"]] == [1]
        assert step["retries"][0]["after"] == ("wait_until: 'sequence_time_s > 0.5' did not "
                                               "hold within 0.2 s")
    retries = [e for e in RunFolder(folder).events() if e["type"] == "step_retry"]
    assert [(e["step"], e["attempt"], e["times"], e["cause"]) for e in retries] == [
        (4, 1, 3, "timeout")]
    assert "      retry 1/3 after: wait_until: 'sequence_time_s > 0.5'" in result.stdout
    # the retried branch was exercised: nothing about it is listed
    assert not any(item.startswith("step ") for item in dry["not_verified"])


def test_a_failed_check_is_retried_as_many_times_as_allowed_then_fails(project, tmp_path):
    path = write(project, "  - check: {that: 'tool.z_mm > 5000', retry: {times: 2}}\n")
    folder = tmp_path / "run"
    result = run_virtual(path, project, folder)
    assert result.exit_code == 3, result.output
    step = report(folder)["steps"][3]
    assert step["status"] == "failed" and len(step["retries"]) == 2
    assert report(folder)["fault"]["halt_confirmed"] is True


def test_a_module_fault_is_never_retried(project, tmp_path):
    """A wait_until that may be retried times out once (retried), then a tow error comes
    during its second attempt: the run halts, exit 3, and no further retry is taken (a
    fault needs the operator's Reset)."""
    path = write(project, "  - wait_until: {until: 'sequence_time_s > 100', timeout_s: 0.3, "
                          "retry: {times: 5}}\n")
    folder = tmp_path / "run"
    result = run_virtual(path, project, folder, "--sim-fault", "4:tow_error@0.5")
    assert result.exit_code == 3, result.output
    data = report(folder)
    assert data["fault"]["cause"] == "tow_error" and data["fault"]["halt_confirmed"] is True
    assert data["steps"][3]["status"] == "failed"
    assert len(data["steps"][3]["retries"]) == 1
    retries = [e for e in RunFolder(folder).events() if e["type"] == "step_retry"]
    assert [e["cause"] for e in retries] == ["timeout"]
    dry = validate_json(path, project, "--sim-fault", "4:tow_error@0.5")["dry_run"]
    assert dry["passed"] is False and dry["fault"]["cause"] == "tow_error"
    assert len(dry["steps"][3]["retries"]) == 1


def test_a_monitor_halt_is_never_retried(project, tmp_path):
    path = write(project, "  - wait_until: {until: 'sequence_time_s > 100', timeout_s: 0.3, "
                          "retry: {times: 5}, monitors: [{while: 'tool.z_mm > 5000'}]}\n")
    folder = tmp_path / "run"
    result = run_virtual(path, project, folder)
    assert result.exit_code == 3, result.output
    data = report(folder)
    assert data["fault"]["cause"] == "monitor" and "retries" not in data["steps"][3]


# --------------------------------------------------------------------------- validation
@pytest.mark.parametrize("step, where, message", [
    ('  - wait: {seconds: 1, if: "tool.z_mm +"}\n', "6:28", "not an expression"),
    ('  - wait: {seconds: 1, skip_if: "pos_deg[9] > 0"}\n', "6:33",
     "joint number 9 is not one of the arm's (1 to 7)"),
    ('  - wait: {seconds: 1, if: "tool.z_mm"}\n', "6:28", "'tool.z_mm' is a number, not a "
                                                         "condition"),
    ("  - wait: {seconds: 1, repeat: {count: true}}\n", "6:40", "expected a whole number, "
                                                               "got true"),
    ("  - wait: {seconds: 1, repeat: {count: 2.0}}\n", "6:40", "expected a whole number"),
    ("  - check: {that: moving, retry: {times: true}}\n", "6:42", "expected a whole number"),
    ("  - wait: {seconds: 1, repeat: {while: moving}}\n", "6:32", "repeat with while needs "
                                                                 "max"),
    ("  - wait: {seconds: 1, repeat: {while: 'tool.z_mm', max: 2}}\n", "6:40",
     "'tool.z_mm' is a number, not a condition"),
    ("  - move: {pose: totem, if: moving}\n", "6:25", "if: a move step moves the arm"),
    ("  - home: {skip_if: moving}\n", "6:12", "skip_if: a home step changes what the "
                                              "modules or arms are told"),
    ("  - wait: {seconds: 1, retry: {times: 1}}\n", "6:24", "retry: a wait step does not "
                                                           "fail in a way that may be retried"),
    ("  - include: {file: startup.yaml, if: moving}\n", "6:14", "an include runs other "
                                                               "steps: put if on those steps"),
])
def test_a_bad_flow_key_is_refused_at_its_line_and_column(project, step, where, message):
    path = write(project, step)
    result = invoke("validate", path, cwd=project)
    assert result.exit_code == 1, result.output
    assert "Traceback" not in result.output
    located = [line for line in result.output.splitlines()
               if line.startswith(f"sequences/f.yaml:{where}: ")]
    assert any(message in line for line in located), result.output


# --------------------------------------------------------------------------- two arms
def test_each_arm_of_a_campaign_says_its_skipped_steps_and_iterations(tmp_path, monkeypatch):
    from twoarmskit import two_arm_campaign

    campaign = two_arm_campaign(tmp_path, monkeypatch)
    (campaign / "sequences" / "flow.yaml").write_text("""\
name: Flow
steps:
  - parallel:
      - arm: A
        steps: [include: startup.yaml, {wait: {seconds: 0.1, skip_if: "pos_deg[2] < 0"}}]
      - arm: B
        steps: [include: startup.yaml, {wait: {seconds: 0.1, repeat: {count: 2}}}]
""")
    result = runner.invoke(app, ["run", "sequences/flow.yaml", "--virtual-time", "--yes",
                                 "--no-report", "--log-dir", str(tmp_path / "run")])
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert any(line.startswith("[A]") and "skipped: skip_if 'pos_deg[2] < 0' was true" in line
               for line in lines), result.output
    assert any(line.startswith("[B]") and line.endswith("(2/2)") for line in lines), \
        result.output


# --------------------------------------------------------------------------- the live view
def test_the_displays_show_the_iteration_and_the_skipped_step(tmp_path):
    from test_display import project, run_with_displays

    path = project(tmp_path, "flow", "  - include: startup.yaml\n"
                                     "  - wait: {seconds: 0.2, repeat: {count: 2}}\n"
                                     "  - wait: {seconds: 0.1, if: 'pos_deg[2] > 0'}\n")
    outcome, view, _, plain_console = run_with_displays(path, tmp_path)
    assert outcome.result.exit_code == 0, outcome.result.message
    # the live view's step line kept the last iteration of the repeated step (the skipped
    # one never started)
    assert view.step_text.endswith(": wait 0.2 s (2/2)"), view.step_text
    plain = plain_console.export_text().splitlines()
    assert "      skipped: if 'pos_deg[2] > 0' was false" in plain, plain
