"""A run folder is evidence: ``seqrun runs`` and ``seqrun report`` never pass off a folder
cut short (a full disk: events, trace and run.mcap stop mid-run while report.json says
passed) or one whose inputs/ were edited afterwards as a plain run, and ``report --mcap``
keeps the bag the run recorded. In process, at virtual time, through the CLI."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers the commands)
from projecttree import ROOT
from seqrun.cli.app import app
from seqrun.runfolder import logfile
from seqrun.runfolder.integrity import changed_inputs, incomplete
from test_console_browser import browser  # noqa: F401 (the fixture)
from test_runlog import FullDisk

TOTEM = ROOT / "sequences" / "totem.yaml"


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> Path:
    """One whole Totem run (record.json, inputs/, events, trace, run.mcap), not touched."""
    folder = tmp_path_factory.mktemp("checks") / "whole"
    result = invoke("run", TOTEM, "--virtual-time", "--yes", "--plain", "--no-report",
                    "--log-dir", folder)
    assert result.exit_code == 0, result.output
    assert (folder / "record.json").is_file() and (folder / "run.mcap").is_file()
    return folder


@pytest.fixture
def run(recorded, tmp_path) -> Path:
    """A copy of the run to change, in a runs folder of its own."""
    folder = tmp_path / "runs" / "20261129-080000-Totem"
    shutil.copytree(recorded, folder)
    return folder


def runs_json(runs_dir: Path) -> list[dict]:
    result = invoke("runs", "--json", "--dir", runs_dir)
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)


def cut_short(folder: Path) -> None:
    """What a full disk leaves of events.jsonl, the trace and run.mcap: each stops mid-run
    (whole lines, the trace at a flush), report.json untouched."""
    events = (folder / "events.jsonl.gz").read_bytes()   # cut at a flush in its first half
    (folder / "events.jsonl.gz").write_bytes(
        events[:events.rfind(b"\x00\x00\xff\xff", 0, len(events) // 2) + 4])
    trace = (folder / "trace.log.gz").read_bytes()
    (folder / "trace.log.gz").write_bytes(trace[:trace.rfind(b"\x00\x00\xff\xff") + 4])
    bag = (folder / "run.mcap").read_bytes()
    (folder / "run.mcap").write_bytes(bag[:len(bag) // 2])


# --------------------------------------------------------------------------- whole runs
@pytest.mark.slow  # draws report.html
def test_a_whole_run_has_no_mark(run):
    assert incomplete(run) == [] and incomplete(run, thorough=True) == []
    assert changed_inputs(run) == []
    [entry] = runs_json(run.parent)
    assert entry["result"] == "passed"
    assert entry["incomplete"] == [] and entry["inputs_changed"] == []
    table = invoke("runs", "--dir", run.parent)
    assert "INCOMPLETE" not in table.stdout and "CHANGED" not in table.stdout
    report = invoke("report", run)
    assert report.exit_code == 0 and "warning" not in report.stderr
    assert 'class="fault banner' not in (run / "report.html").read_text()


# --------------------------------------------------------------------------- incomplete
@pytest.mark.slow  # draws report.html
def test_a_run_cut_short_is_marked_incomplete_in_runs_and_report(run):
    cut_short(run)
    [entry] = runs_json(run.parent)
    assert entry["result"] == "passed"   # the run's own verdict stays
    assert [line.split(":")[0] for line in entry["incomplete"]] == [
        "events.jsonl.gz", "trace.log.gz", "run.mcap"], entry["incomplete"]
    table = invoke("runs", "--dir", run.parent).stdout
    line = next(x for x in table.splitlines() if "Totem" in x)
    assert "passed" in line and "INCOMPLETE: events.jsonl.gz: cut short" in line, table
    assert "(+2 more)" in line and "1 incomplete" in table.splitlines()[-1], table

    report = invoke("report", run)
    assert report.exit_code == 0, report.output
    [warning] = [x for x in report.stderr.splitlines() if x.startswith("warning:")]
    assert "incomplete run folder" in warning and "run.mcap: cut short" in warning
    page = (run / "report.html").read_text()
    assert 'class="fault banner incomplete"' in page and "INCOMPLETE RUN FOLDER" in page
    assert "trace.log.gz: cut short" in page


def test_a_real_full_disk_run_is_marked_incomplete(tmp_path, monkeypatch):
    """Issue 43: on a full disk `seqrun runs` listed a run whose events, trace and MCAP stop
    mid-run as plain "passed"."""
    monkeypatch.setattr(logfile, "_write", FullDisk(40_000))
    result = invoke("run", TOTEM, "--virtual-time", "--yes", "--plain", "--no-report",
                    "--log-dir", tmp_path / "runs" / "full")
    monkeypatch.undo()
    assert result.exit_code == 0, result.output
    [entry] = runs_json(tmp_path / "runs")
    assert entry["result"] == "passed"
    assert entry["incomplete"], entry
    assert any("No space left on device" in x for x in entry["incomplete"])
    assert any(x.startswith("events.jsonl") for x in entry["incomplete"]), entry


def test_log_errors_alone_mark_a_run_incomplete(run):
    report = json.loads((run / "report.json").read_text())
    report["log_errors"] = ["writing run.mcap failed (No space left on device)"]
    (run / "report.json").write_text(json.dumps(report))
    assert incomplete(run) == ["the run could not write its whole log: writing run.mcap "
                               "failed (No space left on device)"]


def test_a_run_still_running_is_not_judged_by_its_log(run):
    report = json.loads((run / "report.json").read_text())
    report["status"] = "running"
    (run / "report.json").write_text(json.dumps(report))
    cut_short(run)
    assert incomplete(run) == []


def test_a_killed_runs_partial_bag_is_named(run):
    (run / "run.mcap").unlink()
    (run / "run.mcap.partial").mkdir()
    assert incomplete(run) == ["run.mcap: not ended (run.mcap.partial/ holds what was "
                               "written)"]


# ----------------------------------------------------------------------- inputs changed
@pytest.mark.slow  # draws report.html
def test_inputs_changed_after_the_run_are_marked_in_runs_and_report(run):
    sequence = run / "inputs" / "sequences" / "totem.yaml"
    assert sequence.is_file(), sorted(p.name for p in (run / "inputs").rglob("*"))
    sequence.write_text(sequence.read_text().replace("Totem", "Totally"))
    (run / "inputs" / "extra.yaml").write_text("name: added later\n")
    [entry] = runs_json(run.parent)
    assert entry["inputs_changed"] == [
        "inputs/sequences/totem.yaml: changed (its sha256 is not record.json's)",
        "inputs/extra.yaml: added (not in record.json)"]
    assert entry["incomplete"] == []
    table = invoke("runs", "--dir", run.parent).stdout
    assert "INPUTS CHANGED: inputs/sequences/totem.yaml: changed" in table, table

    report = invoke("report", run)
    assert report.exit_code == 0, report.output
    [warning] = [x for x in report.stderr.splitlines() if x.startswith("warning:")]
    assert "inputs/ changed after the run" in warning and "totem.yaml: changed" in warning
    page = (run / "report.html").read_text()
    assert 'class="fault banner inputs-changed"' in page
    assert "INPUTS CHANGED AFTER THE RUN" in page


def test_a_missing_input_copy_is_named(run):
    (run / "inputs" / "sequences" / "totem.yaml").unlink()
    assert changed_inputs(run) == ["inputs/sequences/totem.yaml: missing"]


# ------------------------------------------------------------------------ report --mcap
def test_report_mcap_keeps_the_recorded_bag_as_orig(run):
    recorded_bag = (run / "run.mcap").read_bytes()
    first = invoke("report", run, "--mcap")
    assert first.exit_code == 0, first.output
    assert first.stdout.count("\n") == 1, first.stdout   # one line
    assert "run.mcap.orig" in first.stdout and "kept" in first.stdout
    assert (run / "run.mcap.orig").read_bytes() == recorded_bag
    assert (run / "run.mcap").read_bytes()[:8] == b"\x89MCAP0\r\n"

    second = invoke("report", run, "--mcap")   # replaces its own rebuild only
    assert second.exit_code == 0, second.output
    assert "replaces the run.mcap an earlier --mcap wrote" in second.stdout
    assert (run / "run.mcap.orig").read_bytes() == recorded_bag


def test_report_mcap_keeps_a_killed_runs_partial_bag(run):
    (run / "run.mcap").unlink()
    partial = run / "run.mcap.partial"
    partial.mkdir()
    (partial / "run.mcap.partial.mcap").write_bytes(b"\x89MCAP0\r\n what the run wrote")
    result = invoke("report", run, "--mcap")
    assert result.exit_code == 0, result.output
    assert "the run.mcap.partial the run recorded is kept as" in result.stdout
    kept = run / "run.mcap.partial.orig" / "run.mcap.partial.mcap"
    assert kept.read_bytes() == b"\x89MCAP0\r\n what the run wrote"
    assert (run / "run.mcap").is_file() and not partial.exists()


def test_report_mcap_that_fails_puts_the_recorded_bag_back(run):
    recorded_bag = (run / "run.mcap").read_bytes()
    (run / "events.jsonl.gz").write_bytes(b"")   # nothing to write it from
    result = invoke("report", run, "--mcap")
    assert result.exit_code == 2, result.output
    assert (run / "run.mcap").read_bytes() == recorded_bag
    assert not (run / "run.mcap.orig").exists()


# --------------------------------------------------------------------- the console's list
@pytest.mark.slow  # a browser and a server
def test_the_consoles_past_runs_mark_them_too(recorded, tmp_path, browser):  # noqa: F811
    """The console lists the runs folder as `seqrun runs` does, marks included."""
    from consolekit import LiveServer, console_setup

    setup = console_setup(tmp_path / "camp")
    for name, change in (("20261129-080000-Totem", cut_short),
                         ("20261129-090000-Totem", None)):
        shutil.copytree(recorded, setup.runs / name)
        if change is not None:
            change(setup.runs / name)
    (setup.runs / "20261129-090000-Totem" / "inputs" / "sequences" / "totem.yaml").write_text(
        "edited\n")
    try:
        with LiveServer(setup.app()) as server:
            context = browser.new_context(viewport={"width": 1400, "height": 900})
            page = context.new_page()
            page.goto(server.url)
            page.wait_for_function("document.querySelectorAll('#runs li').length === 2",
                                   timeout=20000)
            items = page.eval_on_selector_all("#runs li", "lis => lis.map(li => li.textContent)")
            context.close()
    finally:
        setup.close()
    newest, oldest = items   # newest first
    assert "INPUTS CHANGED" in newest and "INCOMPLETE" not in newest, items
    assert "INCOMPLETE" in oldest and "INPUTS CHANGED" not in oldest, items
