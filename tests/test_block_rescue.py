"""Issue 39 (items 6 and 7, in part): ``block`` with ``rescue`` and ``always``, through
``seqrun validate`` (the dry run) and ``seqrun run --virtual-time`` alike.

A step of a block that fails in a way a rescue may follow (here a failing ``check``) runs
the block's rescue, then its always; the block is reported rescued and the run passes, the
failed step staying failed. A failing rescue fails the run as a failed check does. A
module fault in a block ends with a Halt (exit 3) and neither the rescue nor the always
moves the arm. The dry run lists a rescue it never ran under "not verified"."""

from __future__ import annotations

import contextlib
import shutil
import json
from pathlib import Path

import can
from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers every command)
from runfolder import RunFolder
from seqrun.cli.app import app

runner = CliRunner()

HEAD = """\
name: Blocks
steps:
  - reset
  - home
  - set_limits
"""  # the steps below start on line 6

FAILING = 'check: {that: "pos_deg[2] > 1000", label: Impossible}'
PASSING = 'check: {that: "pos_deg[2] < 1000", label: Always true}'


def write(project: Path, steps: str, name: str = "b.yaml") -> Path:
    path = project / "sequences" / name
    path.write_text(HEAD + steps, encoding="utf-8")
    return path


def invoke(*args, cwd: Path):
    with contextlib.chdir(cwd):
        return runner.invoke(app, [str(a) for a in args])


def validate_json(path: Path, project: Path, *extra: str) -> tuple[int, dict]:
    result = invoke("validate", "--json", path, *extra, cwd=project)
    assert "Traceback" not in result.output
    return result.exit_code, json.loads(result.stdout)


def run_virtual(path: Path, project: Path, folder: Path, *extra: str):
    result = invoke("run", path, "--virtual-time", "--yes", "--plain", "--no-report",
                    "--log-dir", folder, *extra, cwd=project)
    assert "Traceback" not in result.output
    return result


def is_halt(msg: can.Message) -> bool:
    return msg.arbitration_id == 0x100 and msg.data[:1] == b"\x02"


def is_motion(msg: can.Message) -> bool:
    return (0x0E1 <= msg.arbitration_id <= 0x0FF and not msg.is_rx
            and msg.data[:1] == b"\x0b")


def block(steps: str, rescue: str | None = None, always: str | None = None) -> str:
    text = "  - block:\n      label: Capture\n      steps:\n" + steps
    if rescue is not None:
        text += "      rescue:\n" + rescue
    if always is not None:
        text += "      always:\n" + always
    return text


def statuses(steps: list[dict]) -> list[str]:
    return [s["status"] for s in steps]


# --------------------------------------------------------------------------- passing
def test_a_passing_block_skips_its_rescue_runs_its_always_and_lists_the_rescue(project,
                                                                                tmp_path):
    path = write(project, block(f"        - {PASSING}\n",
                                rescue="        - move: {pose: totem, velocity_scale: 0.5}\n",
                                always="        - wait: {seconds: 0.1, label: Always}\n")
                 + "  - wait: 0.1\n")
    code, out = validate_json(path, project)
    dry = out["dry_run"]
    assert code == 0 and dry["passed"] is True, out
    assert any("the rescue of block 1 never ran" in line and "b.yaml:6:5" in line
               for line in dry["not_verified"]), dry["not_verified"]
    folder = tmp_path / "run"
    result = run_virtual(path, project, folder)
    assert result.exit_code == 0, result.output
    for steps, blocks in ((dry["steps"], dry["blocks"]), (RunFolder(folder).report()["steps"],
                                                          RunFolder(folder).report()["blocks"])):
        assert statuses(steps) == ["passed"] * 3 + ["passed", "skipped", "passed", "passed"]
        assert steps[4]["skipped_by"] == "rescue"
        assert steps[3]["block"] == "block 1 (Capture) steps"
        assert steps[4]["block"] == "block 1 (Capture) rescue"
        assert steps[5]["block"] == "block 1 (Capture) always"
        assert "block" not in steps[6]
        assert blocks == [{"block": 1, "label": "Capture", "location": "sequences/b.yaml:6:5",
                           "status": "passed"}]
    # the rescue's motion never reached the bus
    assert not any(e.get("step") == 5 for e in RunFolder(folder).events("step_started"))


# --------------------------------------------------------------------------- rescued
RESCUED = block(f"        - {FAILING}\n        - wait: {{seconds: 0.1, label: Not reached}}\n",
                rescue="        - move: {pose: totem, velocity_scale: 0.5, label: Retreat}\n",
                always="        - wait: {seconds: 0.1, label: Always}\n") + "  - wait: 0.1\n"


def test_a_failing_check_runs_the_rescue_then_the_always_and_the_run_passes(project,
                                                                             tmp_path):
    path = write(project, RESCUED)
    code, out = validate_json(path, project)
    dry = out["dry_run"]
    assert code == 0 and dry["passed"] is True, out
    assert not any("rescue of block 1" in line for line in dry["not_verified"])
    human = invoke("validate", path, cwd=project)
    assert human.exit_code == 0, human.output
    assert ("  block 1 (Capture) at sequences/b.yaml:6:5: rescued (step 4 failed)"
            in human.output.splitlines())
    folder = tmp_path / "run"
    result = run_virtual(path, project, folder)
    assert result.exit_code == 0, result.output
    assert "failed: check failed: pos_deg[2] > 1000 (the block's rescue runs)" in result.output
    assert "block 1 (Capture) at sequences/b.yaml:6:5: rescued" in result.output
    report = RunFolder(folder).report()
    assert report["status"] == "passed" and report["exit_code"] == 0
    for steps, blocks in ((dry["steps"], dry["blocks"]), (report["steps"], report["blocks"])):
        # the failed step stays failed; the step after it in the block is skipped
        assert statuses(steps) == ["passed"] * 3 + ["failed", "skipped", "passed", "passed",
                                                    "passed"]
        assert "pos_deg[2] > 1000" in steps[3]["error"]
        assert steps[4]["skipped_by"] == "block"
        assert blocks[0]["status"] == "rescued" and blocks[0]["failed_step"] == 4
    events = RunFolder(folder).events()
    kinds = [e["type"] for e in events if e["type"].startswith("block_")]
    assert kinds == ["block_step_failed", "block_recheck", "block_finished"]
    # nothing was halted, and the retreat moved the arm after the failure
    assert not any(is_halt(m) for m in RunFolder(folder).trace())
    started = [e["step"] for e in events if e["type"] == "step_started"]
    assert started[-3:] == [6, 7, 8]
    assert RunFolder(folder).events("block_recheck")[0]["errors"] == []


def test_a_failing_rescue_fails_the_run_as_a_failed_check_after_the_always(project,
                                                                             tmp_path):
    path = write(project, block(f"        - {FAILING}\n",
                                rescue=f"        - {FAILING}\n",
                                always="        - wait: {seconds: 0.1, label: Always}\n")
                 + "  - wait: 0.1\n")
    bare = write(project, f"  - {FAILING}\n", name="bare.yaml")
    code, out = validate_json(path, project)
    assert out["dry_run"]["passed"] is False
    folder, bare_folder = tmp_path / "run", tmp_path / "bare"
    result = run_virtual(path, project, folder)
    without_block = run_virtual(bare, project, bare_folder)
    assert result.exit_code == without_block.exit_code == 3, result.output
    report = RunFolder(folder).report()
    assert report["status"] == "failed"
    assert report["fault"]["cause"] == RunFolder(bare_folder).report()["fault"]["cause"]
    assert statuses(report["steps"]) == ["passed"] * 3 + ["failed", "failed", "passed",
                                                          "pending"]
    assert report["blocks"][0]["status"] == "failed"
    assert statuses(out["dry_run"]["steps"]) == statuses(report["steps"])


def test_a_failure_goes_on_to_the_block_around_it(project, tmp_path):
    inner = ("        - block:\n            steps:\n"
             f"              - {FAILING}\n"
             "            always:\n              - wait: {seconds: 0.1, label: Inner always}\n"
             "        - wait: {seconds: 0.1, label: Not reached}\n")
    path = write(project, block(inner, rescue="        - wait: {seconds: 0.1, label: R}\n"))
    folder = tmp_path / "run"
    result = run_virtual(path, project, folder)
    assert result.exit_code == 0, result.output
    report = RunFolder(folder).report()
    assert statuses(report["steps"]) == ["passed"] * 3 + ["failed", "passed", "skipped",
                                                          "passed"]
    assert report["steps"][3]["block"] == "block 1 (Capture) steps > block 2 steps"
    assert [(b["block"], b["status"]) for b in report["blocks"]] == [(2, "failed"),
                                                                     (1, "rescued")]


# --------------------------------------------------------------------------- never rescued
def test_a_module_fault_in_a_block_halts_and_neither_rescue_nor_always_moves(project,
                                                                               tmp_path):
    path = write(project, block("        - move: {pose: totem, velocity_scale: 0.5}\n",
                                rescue="        - move: {pose: opsafe, velocity_scale: 0.5}\n",
                                always="        - move: {pose: park, velocity_scale: 0.5}\n"))
    code, out = validate_json(path, project, "--sim-fault", "4:tow_error@3")
    assert code == 3 and out["dry_run"]["fault"]["cause"] == "tow_error", out
    folder = tmp_path / "run"
    result = run_virtual(path, project, folder, "--sim-fault", "4:tow_error@3")
    assert result.exit_code == 3, result.output
    report = RunFolder(folder).report()
    assert report["fault"]["cause"] == "tow_error" and report["fault"]["halt_sent"] is True
    for steps in (report["steps"], out["dry_run"]["steps"]):
        assert statuses(steps) == ["passed"] * 3 + ["failed", "pending", "pending"]
    assert "blocks" not in report
    events = RunFolder(folder).events()
    assert [e["step"] for e in events if e["type"] == "step_started"] == [1, 2, 3, 4]
    assert not any(e["type"].startswith("block_") for e in events)
    trace = RunFolder(folder).trace()
    halts = [i for i, m in enumerate(trace) if is_halt(m)]
    assert halts and any(is_motion(m) for m in trace[:halts[0]])
    assert not any(is_motion(m) for m in trace[halts[0]:])


# --------------------------------------------------------------------------- validation
def test_a_rescue_step_is_checked_though_the_normal_path_never_runs_it(project):
    path = write(project, block(f"        - {PASSING}\n",
                                rescue="        - move: {joints: {j2: 400}}\n"))
    code, out = validate_json(path, project)
    assert code == 1
    assert any(e["line"] == 11 and "j2" in e["message"] for e in out["errors"]), out["errors"]


def test_the_block_shape_is_refused_at_its_line(project):
    cases = {
        "  - block:\n      rescue:\n        - wait: 0.1\n": (7, "missing required key 'steps'"),
        "  - block:\n      steps: []\n": (7, "must not be empty"),
        "  - block:\n      steps:\n        - wait: 0.1\n      rescue: []\n": (9, "must not be empty"),
        "  - block:\n      if: \"pos_deg[2] > 0\"\n      steps:\n        - wait: 0.1\n":
            (7, "put if on its steps"),
        "  - block:\n      steps:\n        - wiat: 0.1\n": (8, "did you mean 'wait'"),
    }
    for steps, (line, text) in cases.items():
        path = write(project, steps)
        result = invoke("validate", "--static", path, cwd=project)
        assert result.exit_code == 1, (steps, result.output)
        assert "Traceback" not in result.output
        lines = [x for x in result.output.splitlines() if text in x]
        assert lines and lines[0].startswith(f"sequences/b.yaml:{line}:"), (steps, result.output)


def test_a_campaign_of_several_arms_refuses_a_rescue_at_its_line(tmp_path):
    from projecttree import ROOT

    campaign = tmp_path / "two"
    shutil.copytree(ROOT / "examples" / "two-arms", campaign,
                    ignore=shutil.ignore_patterns("runs"))
    path = campaign / "sequences" / "hold_and_approach.yaml"
    text = path.read_text(encoding="utf-8")
    move = "          - move: {pose: totem, velocity_scale: 0.5, label: A up to Totem}\n"
    assert move in text
    path.write_text(text.replace(move, "          - block:\n              steps:\n"
                                       "        " + move + "              rescue:\n"
                                       "                - wait: 0.1\n", 1), encoding="utf-8")
    result = invoke("validate", "--static", path, cwd=campaign)
    assert result.exit_code == 1, result.output
    assert ("sequences/hold_and_approach.yaml:22:19: a block's rescue in a campaign of "
            "several arms") in result.output


def test_an_operator_abort_in_a_block_stops_the_arm_without_rescue_or_always(project,
                                                                               tmp_path):
    from seqrun.results import EXIT_OPERATOR_ABORT
    from simrun import run_on_sim

    write(project, block("        - move: {pose: totem, velocity_scale: 0.5}\n",
                         rescue="        - move: {pose: opsafe, velocity_scale: 0.5}\n",
                         always="        - move: {pose: park, velocity_scale: 0.5}\n"))

    def abort_during_the_move(executor):
        def listener(event):
            if event["type"] == "setpoint" and event["plan_t"] >= 2.0 and event.get("step") == 4:
                executor.abort("operator abort")
        executor.listeners.append(listener)

    outcome, _, _ = run_on_sim("b", tmp_path, root=project, on_executor=abort_during_the_move)
    assert outcome.result.exit_code == EXIT_OPERATOR_ABORT, outcome.result.message
    folder = RunFolder(outcome.log_dir)
    assert statuses(folder.report()["steps"]) == ["passed"] * 3 + ["aborted", "pending",
                                                                  "pending"]
    events = folder.events()
    assert [e["step"] for e in events if e["type"] == "step_started"] == [1, 2, 3, 4]
    assert any(e["type"] == "controlled_stop" for e in events)
    assert not any(e["type"].startswith("block_") for e in events)


def test_the_path_after_an_early_failure_is_checked_from_the_measured_arm(project, tmp_path):
    """Validation checks the rescue after the block's last step (the arm up at Op-safe, where
    going 100 mm down is clear); the check fails before the move, with the arm at Park,
    where it is not: the run refuses the rescue before anything moves."""
    down = ("        - move_linear: {position_mm: [0, 0, -100], relative: true, "
            "frame: base, speed_mm_s: 5}\n")
    path = write(project, block(f"        - {FAILING}\n"
                                "        - move: {pose: opsafe, velocity_scale: 0.5}\n",
                                rescue=down))
    code, out = validate_json(path, project, "--static")
    assert code == 0, out
    folder = tmp_path / "run"
    result = run_virtual(path, project, folder)
    assert result.exit_code == 3, result.output
    report = RunFolder(folder).report()
    assert report["fault"]["cause"] == "block_recheck"
    assert "not valid from where the arm stands" in report["message"]
    recheck = RunFolder(folder).events("block_recheck")
    assert len(recheck) == 1 and recheck[0]["errors"], recheck
    assert statuses(report["steps"]) == ["passed"] * 3 + ["failed", "skipped", "failed"]
    # nothing moved after the failed check
    trace = RunFolder(folder).trace()
    assert not any(is_motion(m) for m in trace)


def test_a_wait_until_that_times_out_is_rescued_and_report_html_says_so(project, tmp_path):
    path = write(project, block('        - wait_until: {until: "pos_deg[2] > 1000", '
                                "timeout_s: 0.5, label: Never}\n",
                                rescue="        - wait: {seconds: 0.1, label: Rescue}\n"))
    folder = tmp_path / "run"
    result = run_virtual(path, project, folder)
    assert result.exit_code == 0, result.output
    report = RunFolder(folder).report()
    assert statuses(report["steps"]) == ["passed"] * 3 + ["failed", "passed"]
    assert report["blocks"][0]["status"] == "rescued"
    drawn = invoke("report", folder, cwd=project)
    assert drawn.exit_code == 0, drawn.output
    html = (folder / "report.html").read_text(encoding="utf-8")
    table = html[html.index('<table id="blocks">'):]
    table = table[:table.index("</table>")]
    assert "rescued" in table and "sequences/b.yaml:6:5" in table


def test_the_paths_of_nested_blocks():
    from types import SimpleNamespace

    from seqrun.steps.blocks import has_rescue, normal_path, rescue_paths
    from seqrun.steps.resolved import BlockFrame
    from seqrun.yamlsource import Location

    def frame(block: int, part: str) -> BlockFrame:
        return BlockFrame(block, part, Location("f.yaml", block, 1))

    a_steps, a_rescue, a_always = frame(1, "steps"), frame(1, "rescue"), frame(1, "always")
    steps = [SimpleNamespace(n=1, blocks=(a_steps,)),
             SimpleNamespace(n=2, blocks=(a_rescue,)),
             SimpleNamespace(n=3, blocks=(a_rescue, frame(2, "steps"))),
             SimpleNamespace(n=4, blocks=(a_rescue, frame(2, "rescue"))),
             SimpleNamespace(n=5, blocks=(a_always,)),
             SimpleNamespace(n=6, blocks=())]
    assert has_rescue(steps) and not has_rescue([steps[0], steps[5]])
    assert [s.n for s in normal_path(steps)] == [1, 5, 6]
    paths = {block: [s.n for s in path] for block, path in rescue_paths(steps).items()}
    # block 2 sits in block 1's rescue: its rescue runs only after block 1's failed
    assert paths == {1: [1, 2, 3, 5, 6], 2: [1, 2, 3, 4, 5, 6]}
