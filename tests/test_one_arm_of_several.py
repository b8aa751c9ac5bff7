"""One arm of a campaign with several ([arms.ID]): every command that acts on one arm takes
``--arm-id ID`` and then uses that arm's arm file, bus and zero; a run says which arm it
moved, and ``seqrun runs`` lists the runs of one arm and of several (each arm's, and those
it was part of). The refusal "name one (--arm-id ID)" names an option the command has."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from typer.testing import CliRunner

from projecttree import ROOT
from seqrun.cli import app
from twoarmskit import two_arm_campaign

#: A sequence of one arm: valid on A (j1 within ±180°), not on B (its arm file: ±20°).
NUDGE = """\
name: Nudge
description: j1 to 45° and back.
steps:
  - include: startup.yaml
  - move: {joints: {j1: 45}}
  - move: {joints: {j1: 0}}
"""


def invoke(*args: object):
    return CliRunner().invoke(app, [str(a) for a in args])


@pytest.fixture
def campaign(tmp_path, monkeypatch) -> Path:
    """The example campaign of two arms, B with an arm file of its own whose j1 turns
    ±20° only, and the one-arm sequence ``nudge.yaml``."""
    folder = two_arm_campaign(tmp_path, monkeypatch)
    text = (ROOT / "arms" / "lwa3.yaml").read_text()
    j1 = "{name: j1, module: 1, limits_deg: [-180, 180],"
    assert j1 in text
    (folder / "arms").mkdir(exist_ok=True)
    (folder / "arms" / "lwa3_narrow.yaml").write_text(
        text.replace(j1, "{name: j1, module: 1, limits_deg: [-20, 20],"))
    toml = (folder / "seqrun.toml").read_text()
    b = toml.index("[arms.B]")
    (folder / "seqrun.toml").write_text(
        toml[:b] + toml[b:].replace('arm = "lwa3"', 'arm = "lwa3_narrow"', 1))
    (folder / "sequences" / "nudge.yaml").write_text(NUDGE)
    return folder


def one_line_error(result) -> str:
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), result.output
    assert "Traceback" not in result.output
    return lines[0]


#: Every command that acts on one arm, as an operator types it in a campaign of several
#: arms without naming one (each bus its own built-in simulator: nothing else is needed).
ONE_ARM_COMMANDS = [
    ["run", "sequences/nudge.yaml", "--virtual-time", "--yes", "--plain"],
    ["pose", "show", "totem"],
    ["pose", "save", "here", "--sim"],
    ["limits", "show", "--sim"],
    ["limits", "set", "--sim"],
    ["zero", "show"],
    ["zero", "set", "totem", "--yes"],
    ["jog", "j1", "5", "--for", "0.1", "--sim"],
    ["ros", "--sim"],
]


@pytest.mark.parametrize("command", ONE_ARM_COMMANDS, ids=" ".join)
def test_a_command_of_one_arm_asks_which_and_has_the_option_it_names(campaign, command):
    refused = invoke(*command)
    assert refused.exit_code == 2
    assert "has arms A, B: name one (--arm-id ID)" in one_line_error(refused)
    words = [w for w in command if not w.startswith(("-", "sequences/"))][:2]
    words = words[:1] if words[0] in ("run", "jog", "ros") else words
    helped = invoke(*words, "--help")
    assert helped.exit_code == 0 and "--arm-id" in helped.output, helped.output


def test_pose_list_and_runs_need_no_arm(campaign):
    """The poses and the run folders are the campaign's, every arm's."""
    poses = invoke("pose", "list")
    assert poses.exit_code == 0 and re.search(r"^totem ", poses.output, re.M), poses.output
    runs = invoke("runs")
    assert runs.exit_code == 0 and "no runs in" in runs.output, runs.output


def test_a_one_arm_run_on_b_uses_bs_arm_file_and_says_so(campaign):
    on_b = invoke("run", "sequences/nudge.yaml", "--arm-id", "B", "--virtual-time", "--yes",
                  "--plain")
    assert on_b.exit_code == 1, on_b.output  # j1 45° lies outside B's ±20°
    assert "j1" in on_b.output and "nothing was sent" in on_b.output
    on_a = invoke("run", "sequences/nudge.yaml", "--arm-id", "A", "--virtual-time", "--yes",
                  "--plain")
    assert on_a.exit_code == 0, on_a.output
    assert on_a.output.lstrip().startswith("arm A: ")
    folder = Path(re.search(r"log: (\S+)", on_a.output).group(1))
    assert json.loads((folder / "record.json").read_text())["arm_id"] == "A"
    # the refusal on B is recorded as B's
    records = [json.loads(p.read_text()) for p in (campaign / "runs").glob("*/record.json")]
    assert sorted(r.get("arm_id") for r in records) == ["A", "B"]
    # validate checks against the arm named, as the run does
    assert invoke("validate", "sequences/nudge.yaml", "--arm-id", "B").exit_code == 1
    assert invoke("validate", "sequences/nudge.yaml", "--arm-id", "A").exit_code == 0
    unknown = invoke("validate", "sequences/nudge.yaml", "--arm-id", "C")
    assert unknown.exit_code == 2 and "unknown arm 'C'" in one_line_error(unknown)
    # no arm named: the arms' arm files differ, so which arm it is checked for is asked
    which = invoke("validate", "sequences/nudge.yaml")
    assert which.exit_code == 2
    assert "different arm files (A: " in one_line_error(which) and "(--arm-id ID)" in \
        one_line_error(which)


def test_a_campaigns_validation_checks_a_one_arm_sequence_for_each_arm_file(campaign):
    """seqrun validate DIR (or several files): a sequence of one arm is checked against
    every arm file of the campaign's arms, each finding naming its arms."""
    checked = invoke("validate", "sequences/nudge.yaml", "sequences/startup.yaml", "--json")
    assert checked.exit_code == 1, checked.output
    nudge, startup = json.loads(checked.output)["results"]
    assert nudge["result"] == "invalid" and startup["result"] == "valid"
    assert nudge["errors"] == ["arm B: sequences/nudge.yaml:5:25: j1 target 45° is outside "
                               "its limits -20…20"]


def test_fk_and_ik_use_the_arm_named(campaign):
    """B's j1 turns ±20°: fk notes 30° as outside on B, not on A; with the arms' arm files
    different, no arm named is asked for."""
    on_b = invoke("fk", "--deg", "30", "0", "0", "0", "0", "0", "0", "--arm-id", "B")
    assert on_b.exit_code == 0 and "j1 30 deg is outside its limits [-20, 20]" in on_b.output
    on_a = invoke("fk", "--deg", "30", "0", "0", "0", "0", "0", "0", "--arm-id", "A")
    assert on_a.exit_code == 0 and "outside" not in on_a.output, on_a.output
    for command in (["fk", "--deg", "0", "0", "0", "0", "0", "0", "0"],
                    ["ik", "--position-mm", "300", "0", "600", "--rpy-deg", "180", "0", "0"]):
        which = invoke(*command)
        assert which.exit_code == 2 and "different arm files" in one_line_error(which)
    both = invoke("fk", "--deg", "0", "0", "0", "0", "0", "0", "0", "--arm-id", "A", "--arm",
                  ROOT / "arms" / "lwa3.yaml")
    assert both.exit_code == 2 and "leave out --arm" in one_line_error(both)
    reached = invoke("ik", "--position-mm", "300", "0", "600", "--rpy-deg", "180", "0", "0",
                     "--arm-id", "A")
    assert reached.exit_code == 0, reached.output


def test_a_sequence_of_one_arm_validates_against_the_arm_file_all_arms_share(tmp_path,
                                                                           monkeypatch):
    two_arm_campaign(tmp_path, monkeypatch)
    checked = invoke("validate", "sequences/startup.yaml", "--static")
    assert checked.exit_code == 0 and "valid (3 steps)" in checked.output, checked.output
    assert invoke("fk", "--deg", "0", "0", "0", "0", "0", "0", "0").exit_code == 0


def test_arm_id_is_refused_for_a_sequence_that_names_the_arms(campaign):
    for command in ("run", "validate"):
        refused = invoke(command, "sequences/short.yaml", "--arm-id", "B", "--virtual-time"
                         if command == "run" else "--static")
        assert refused.exit_code == 2
        assert "names the arms it moves" in one_line_error(refused)


def test_runs_lists_the_runs_of_one_arm_and_of_several(campaign):
    assert invoke("run", "sequences/startup.yaml", "--arm-id", "B", "--virtual-time",
                  "--yes", "--plain").exit_code == 0
    both = invoke("run", "sequences/short.yaml", "--virtual-time", "--yes", "--plain")
    assert both.exit_code == 0, both.output
    listed = invoke("runs", "--json")
    assert listed.exit_code == 0, listed.output
    runs = json.loads(listed.output)
    assert [(r["sequence"], r["arm"], r["arms"], r["result"]) for r in runs] == [
        ("Start-up", "B", None, "passed"), ("Short", None, ["A", "B"], "passed")]
    assert runs[1]["exit_code"] == 0 and runs[1]["simulator"] is True
    assert runs[1]["duration_s"] > 0
    of_a = json.loads(invoke("runs", "--json", "--arm-id", "A").output)
    assert [r["sequence"] for r in of_a] == ["Short"]
    of_b = json.loads(invoke("runs", "--json", "--arm-id", "B").output)
    assert [r["sequence"] for r in of_b] == ["Start-up", "Short"]
    table = invoke("runs").output.splitlines()
    assert table[0].split()[-1] == "arm"
    assert table[1].split()[-1] == "B" and table[2].split()[-1] == "A,B"
    wrong = invoke("runs", "--arm-id", "C")
    assert wrong.exit_code == 2 and "has arms A, B" in one_line_error(wrong)


def test_a_run_of_several_arms_under_way_or_broken_is_listed(campaign):
    """Its parts say it runs until arms.json is written at the end; a folder whose
    arms.json cannot be read is listed as corrupted, never hidden."""
    from seqrun.service.records import list_runs

    assert invoke("run", "sequences/short.yaml", "--virtual-time", "--yes",
                  "--plain").exit_code == 0
    (folder,) = (campaign / "runs").iterdir()
    summary = (folder / "arms.json").read_text()
    (folder / "arms.json").write_text(summary[:40])
    (entry,) = list_runs(campaign / "runs")
    assert entry["result"] == "corrupted" and "arms.json: not JSON" in entry["problem"]
    (folder / "arms.json").unlink()
    report = json.loads((folder / "B" / "report.json").read_text())
    (folder / "B" / "report.json").write_text(json.dumps(report | {"status": "running"}))
    (entry,) = list_runs(campaign / "runs")
    assert entry["result"] == "running" and entry["arms"] == ["A", "B"]
    # a folder that only groups runs (a --log-dir of several) is no run of several arms
    group = campaign / "runs" / "group"
    (group / "one").mkdir(parents=True)
    (group / "one" / "report.json").write_text((folder / "A" / "report.json").read_text())
    assert [e["folder"] for e in list_runs(campaign / "runs")] == [str(folder)]
