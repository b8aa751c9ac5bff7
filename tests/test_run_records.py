"""Run records: the inputs frozen with their sha256, git state, bus and zero reference;
a short record for a run refused by validation; ``seqrun runs``."""

from __future__ import annotations

import hashlib
import json
import subprocess
from pathlib import Path

import pytest
from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers the commands)
from runfolder import RunFolder
from seqrun import __version__
from seqrun.cli.app import app
from seqrun.service.records import freeze_inputs, git_state, list_runs


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


def git(folder: Path, *args: str) -> str:
    return subprocess.run(["git", "-C", str(folder), *args], check=True, capture_output=True,
                          text=True).stdout.strip()


@pytest.fixture
def campaign(tmp_path, monkeypatch) -> Path:
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("SEQRUN_STATE_DIR", str(tmp_path / "state"))
    assert invoke("init", tmp_path / "camp").exit_code == 0
    camp = tmp_path / "camp"
    git(camp, "init", "-q")
    git(camp, "-c", "user.email=t@example.org", "-c", "user.name=t", "add", ".")
    git(camp, "-c", "user.email=t@example.org", "-c", "user.name=t", "commit", "-qm", "start")
    return camp


def test_a_run_freezes_every_input_with_its_sha256(campaign):
    result = invoke("run", campaign / "sequences" / "first.yaml", "--yes", "--virtual-time",
                    "--plain", "--no-report")
    assert result.exit_code == 0, result.output
    (folder,) = (campaign / "runs").iterdir()  # the campaign's run folder location
    record = json.loads((folder / "record.json").read_text())
    copies = {entry["copy"]: entry for entry in record["inputs"]}
    assert {"inputs/sequences/first.yaml", "inputs/sequences/startup.yaml",
            "inputs/seqrun.toml", "inputs/_shipped/arms/lwa3.yaml",
            "inputs/_shipped/poses/totem.yaml"} <= set(copies)
    for entry in record["inputs"]:
        data = (folder / entry["copy"]).read_bytes()
        assert hashlib.sha256(data).hexdigest() == entry["sha256"]
        assert data == Path(entry["path"]).read_bytes()
    assert record["seqrun"] == __version__
    assert record["git"] == {"commit": git(campaign, "rev-parse", "HEAD"), "dirty": False}
    assert record["bus"].startswith("SIMULATOR")
    assert record["zero"]["pose"] == "park" and record["campaign"] == str(campaign.resolve())


def test_a_dirty_work_tree_is_flagged_and_no_repository_is_none(campaign, tmp_path):
    (campaign / "sequences" / "first.yaml").write_text(
        (campaign / "sequences" / "first.yaml").read_text() + "\n")
    assert git_state(campaign)["dirty"] is True
    (tmp_path / "plain").mkdir()
    assert git_state(tmp_path / "plain") is None


def test_freeze_inputs_takes_a_list_of_paths_and_drops_duplicates(tmp_path):
    a = tmp_path / "proj" / "a.yaml"
    a.parent.mkdir()
    a.write_text("x: 1\n")
    entries = freeze_inputs(tmp_path / "run", [a, a, tmp_path / "missing.yaml"],
                            root=tmp_path / "proj")
    assert [e["copy"] for e in entries] == ["inputs/a.yaml"]
    assert entries[0]["sha256"] == hashlib.sha256(b"x: 1\n").hexdigest()


def test_a_run_refused_by_validation_leaves_a_short_record(campaign):
    bad = campaign / "sequences" / "bad.yaml"
    bad.write_text("name: Bad\ndescription: x\nsteps:\n  - include: startup.yaml\n"
                   "  - move: {joints: {j2: 150}}\n")
    result = invoke("run", bad, "--yes", "--virtual-time")
    assert result.exit_code == 1
    (folder,) = (campaign / "runs").iterdir()
    report = RunFolder(folder).report()
    assert report["status"] == "refused" and report["exit_code"] == 1
    assert "j2 target 150° is outside its limits" in report["errors"][0]["message"]
    assert RunFolder(folder).trace_path() is None  # nothing was sent
    assert (folder / "inputs" / "sequences" / "bad.yaml").read_text() == bad.read_text()


def test_an_unloadable_sequence_is_recorded_as_refused_too(campaign):
    broken = campaign / "sequences" / "broken.yaml"
    broken.write_text("name: [\n")
    assert invoke("run", broken, "--yes").exit_code == 1
    (folder,) = (campaign / "runs").iterdir()
    report = RunFolder(folder).report()
    assert report["status"] == "refused" and report["errors"]


def test_runs_lists_past_runs(campaign, monkeypatch):
    invoke("run", campaign / "sequences" / "first.yaml", "--yes", "--virtual-time", "--plain",
           "--no-report")
    bad = campaign / "sequences" / "bad.yaml"
    bad.write_text("name: Bad\ndescription: x\nsteps:\n  - move: totem\n")
    invoke("run", bad, "--yes", "--virtual-time")
    monkeypatch.chdir(campaign / "sequences")  # the campaign is found upward
    listed = json.loads(invoke("runs", "--json").output)
    assert [(r["sequence"], r["result"], r["exit_code"]) for r in listed] == [
        ("First", "passed", 0), ("Bad", "refused", 1)]
    assert listed[0]["duration_s"] > 8 and listed[0]["when"]
    text = invoke("runs").output
    assert "First" in text and "refused" in text and "2 runs in" in text
    assert list_runs(campaign / "nothing") == []


def test_runs_marks_corrupted_folders_and_lists_the_rest(campaign, monkeypatch):
    """Issue 23 (item 6): one broken report.json must not hide (or crash) the listing."""
    invoke("run", campaign / "sequences" / "first.yaml", "--yes", "--virtual-time", "--plain",
           "--no-report")
    runs = campaign / "runs"
    broken = {"a-list": "[1, 2]", "b-garbage": "\x00\x01{not json", "c-types":
              json.dumps({"status": "passed", "start": 5, "duration_s": "long",
                          "exit_code": True, "sequence": {"x": 1}}),
              "d-deep": "[" * 100_000 + "]" * 100_000, "e-binary": None}
    for name, text in broken.items():
        (runs / name).mkdir()
        if text is None:
            (runs / name / "report.json").write_bytes(b"\xff\xfe\x00garbage")
        else:
            (runs / name / "report.json").write_text(text)
    (runs / "f-killed").mkdir()
    (runs / "f-killed" / "events.jsonl").write_text('{"type": "run_started"}\n')
    (runs / "not-a-run").mkdir()  # an empty folder is no run: not listed
    monkeypatch.chdir(campaign)
    result = invoke("runs")
    assert result.exit_code == 0, result.output
    assert "Traceback" not in result.output
    lines = result.output.splitlines()
    # (c-types says passed with no events.jsonl at all: incomplete, not corrupted)
    assert lines[-1].startswith("7 runs in ") and ", 5 corrupted, 1 incomplete " in lines[-1]
    for name in ("a-list", "b-garbage", "d-deep", "e-binary", "f-killed"):
        line = next(line for line in lines if f"({name})" in line)
        assert " corrupted " in line, line
    assert any("First" in line and "passed" in line for line in lines)
    listed = json.loads(invoke("runs", "--json").output)
    by_folder = {Path(r["folder"]).name: r for r in listed}
    assert by_folder["f-killed"]["problem"] == "no report.json"
    # Fields of the wrong type are shown as unknown, never crash the table.
    assert by_folder["c-types"]["result"] == "passed" and "problem" not in by_folder["c-types"]
    assert by_folder["c-types"]["duration_s"] is None and by_folder["c-types"]["when"] is None
    assert by_folder["c-types"]["exit_code"] is None and by_folder["c-types"]["sequence"] is None
    assert "not-a-run" not in by_folder


def test_runs_says_simulator_or_real_bus(campaign, monkeypatch):
    """Issue 23 (item 8): which runs moved a real arm, at a glance."""
    invoke("run", campaign / "sequences" / "first.yaml", "--yes", "--virtual-time", "--plain",
           "--no-report")
    real = campaign / "runs" / "zz-real"
    real.mkdir()
    (real / "report.json").write_text(json.dumps({
        "sequence": "Real", "status": "passed", "exit_code": 0, "duration_s": 3.0,
        "start": "2099-01-01T00:00:00+00:00"}))
    (real / "record.json").write_text(json.dumps({"bus": "ixxat channel 0, 1000000 bit/s"}))
    (real / "events.jsonl").write_text('{"t": 3.0, "type": "run_finished"}\n')  # whole
    monkeypatch.chdir(campaign)
    listed = json.loads(invoke("runs", "--json").output)
    assert [(r["sequence"], r["simulator"]) for r in listed] == [("First", True),
                                                                 ("Real", False)]
    lines = invoke("runs").output.splitlines()
    assert lines[0].split()[-1] == "bus"
    assert lines[1].split()[-1] == "sim" and lines[2].split()[-1] == "REAL"
