"""Reports of a run folder: report.html, CSV export, JUnit, report.json's tracking figures.

The runs are real ``seqrun run --virtual-time`` runs through the CLI (in process); the
numbers the report shows are held against a recomputation from the raw events.jsonl
written here with plain numpy (a least-squares fit per window, no code shared with
seqrun/arm/tracking.py).
"""

from __future__ import annotations

import csv
import gzip
import json
import re
import shutil
import xml.etree.ElementTree as ET
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers the commands)
from projecttree import ROOT, shipped_arm
from runfolder import RunFolder
from seqrun.cli.app import app
from seqrun.report import load_run, write_html
from seqrun.report.figures import decimate
from seqrun.report.readings import Series

OPSAFE = ROOT / "sequences" / "opsafe.yaml"
ARM = shipped_arm()
JOINTS = ARM.joint_names
#: 7 joints + the guard points (virtual time: no loop-period histogram).
TIME_PLOTS = [f"plot-{n}" for n in JOINTS] + ["plot-guards"]


def cli_run(folder: Path, *extra: str) -> object:
    result = CliRunner().invoke(app, ["run", str(OPSAFE), "--virtual-time", "--yes", "--plain",
                                      "--log-dir", str(folder), *extra])
    assert result.exception is None or isinstance(result.exception, SystemExit), result.output
    return result


@pytest.fixture(scope="module")
def clean_run(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("clean") / "run"
    assert cli_run(folder).exit_code == 0
    return folder


@pytest.fixture(scope="module")
def fault_run(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("fault") / "run"
    assert cli_run(folder, "--sim-fault", "4:tow_error@5").exit_code == 3
    return folder


class Page(HTMLParser):
    """The parts of report.html the tests read: ids, per-joint figures, plots."""

    def __init__(self, text: str) -> None:
        super().__init__()
        self.ids: set[str] = set()
        self.figures: dict[tuple[int, str, str | None], str] = {}
        self.plots: list[str] = []
        self.svgs = 0
        self.external: list[str] = []
        self._cell: tuple | None = None
        self._text = ""
        self.feed(text)

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if "id" in a:
            self.ids.add(a["id"])
        if tag == "svg":
            self.svgs += 1
        if tag == "figure" and "plot" in (a.get("class") or ""):
            self.plots.append(a["id"])
        if tag in ("script", "link", "img", "iframe", "object", "embed"):
            self.external.append(tag)
        for key in ("src", "href"):
            if a.get(key) and not a[key].startswith("#"):
                self.external.append(a[key])
        if "data-figure" in a:
            self._cell = (int(a["data-step"]), a["data-figure"], a.get("data-joint"))
            self._text = ""

    def handle_data(self, data):
        if self._cell is not None:
            self._text += data

    def handle_endtag(self, tag):
        if tag == "td" and self._cell is not None:
            self.figures[self._cell] = self._text.strip()
            self._cell = None


def page(folder: Path) -> tuple[str, Page]:
    text = (folder / "report.html").read_text(encoding="utf-8")
    return text, Page(text)


# ---------------------------------------------------------------------------------------
# Independent recomputation from events.jsonl (numpy only)
def recompute(folder: Path) -> dict[int, dict[str, np.ndarray]]:
    log = RunFolder(folder).events()
    window = next(e for e in log if e["type"] == "run_started")["velocity_window_s"]
    out: dict[int, dict[str, np.ndarray]] = {}
    for planned_event in (e for e in log if e["type"] == "move_planned"):
        step = planned_event["step"]
        cycles = [e for e in log if e["type"] == "setpoint" and e["step"] == step]
        planned = np.array([e["planned_deg"] for e in cycles])
        measured = np.array([e["measured_deg"] for e in cycles])
        # when the joints answered (read_t: one time, or one per joint), as the log says
        per_joint = np.array([np.broadcast_to(e["read_t"], measured.shape[1:])
                              for e in cycles], dtype=float)
        t = np.round(per_joint.mean(axis=1), 6)
        peak = np.zeros(measured.shape[1])
        for k in range(len(t)):
            inside = (t >= t[k] - window - 1e-9) & (t <= t[k])
            if t[k] - t[inside].min() < window / 2 - 1e-9:
                continue
            slopes = [np.polyfit(per_joint[inside, j], measured[inside, j], 1)[0]
                      for j in range(measured.shape[1])]
            peak = np.maximum(peak, np.abs(slopes))
        out[step] = {
            "max_following_error_deg": np.abs(planned - measured).max(axis=0),
            "final_error_deg": np.abs(np.array(planned_event["target_deg"]) - measured[-1]),
            "peak_measured_velocity_deg_s": peak,
        }
    return out


@pytest.mark.parametrize("which", ["clean_run", "fault_run"])
def test_report_numbers_equal_a_recomputation_from_the_events(which, request):
    folder = request.getfixturevalue(which)
    expected = recompute(folder)
    assert expected, "no move in the log"
    report = RunFolder(folder).report()
    steps = {s["number"]: s for s in report["steps"]}
    _, html = page(folder)
    for step, figures in expected.items():
        for key, values in figures.items():
            # report.json: the executor's figures, from the values it logged.
            np.testing.assert_allclose(steps[step][key], values, atol=1.5e-3, err_msg=key)
            # report.html: the same numbers, per joint.
            shown = [float(html.figures[(step, key, name)]) for name in JOINTS]
            np.testing.assert_allclose(shown, values, atol=1.5e-3, err_msg=key)
        s = steps[step]
        if s["status"] == "passed":
            ratio = s["executed_duration_s"] / s["planned_duration_s"]
            assert s["duration_ratio"] == pytest.approx(ratio, abs=1e-4)
            assert float(html.figures[(step, "duration_ratio", None)]) == pytest.approx(
                ratio, abs=1e-4)
    # A clean run's moves end in position; the faulted one shows how far it still was.
    if which == "clean_run":
        for step in expected:
            assert max(steps[step]["final_error_deg"]) <= ARM.control.position_tolerance_deg


def test_an_aborted_move_has_its_figures_up_to_the_stop(tmp_path):
    # Operator abort 2 s into the first move: controlled stop, exit 130. The move's step
    # result carries the figures of what was streamed (the stop included), the page draws.
    from seqrun.clock import VirtualClock
    from seqrun.service.connection import open_connection
    from seqrun.service.runner import run_sequence
    from seqrun.sequence.loader import load_sequence

    def abort_at_two_seconds(executor):
        def listener(event):
            if event["type"] == "setpoint" and event["plan_t"] >= 2.0 and event["step"] == 5:
                executor.abort("test: operator abort")
        executor.listeners.append(listener)

    connection = open_connection(force_sim=True, clock=VirtualClock())
    try:
        outcome = run_sequence(load_sequence(OPSAFE), ARM, connection, log_dir=tmp_path / "run",
                               confirm=lambda prompt: True, on_executor=abort_at_two_seconds)
    finally:
        connection.close()
    assert outcome.result.exit_code == 130 and outcome.report_error is None
    folder = outcome.log_dir
    step = RunFolder(folder).report()["steps"][4]
    assert step["status"] == "aborted"
    expected = recompute(folder)[5]
    for key, values in expected.items():
        np.testing.assert_allclose(step[key], values, atol=1.5e-3, err_msg=key)
    text, html = page(folder)
    assert "ABORTED" in text and html.plots == TIME_PLOTS


def test_report_html_of_a_clean_run_is_self_contained_with_every_plot(clean_run):
    text, html = page(clean_run)
    assert html.plots == TIME_PLOTS
    assert html.svgs == len(TIME_PLOTS)
    assert html.external == []                     # nothing fetched: opens offline
    assert not re.search(r"url\((?!#)|@import|@font-face", text)   # only in-page refs
    assert "PASSED" in text and "fault" not in html.ids
    assert {"identity", "steps", "checkpoints"} <= html.ids
    assert "sequences/opsafe.yaml" in text and "exit code 0" in text
    # The checkpoint table shows expected, measured, error and tolerance.
    report = RunFolder(clean_run).report()
    [checkpoint] = report["checkpoints"]
    table = text[text.index('id="checkpoints"'):]
    for key in ("position_tolerance_mm", "angle_tolerance_deg"):
        assert f"{checkpoint[key]:.3f}" in table or f"{checkpoint[key]:.4f}" in table
    assert str(checkpoint["expected_position_mm"][0]) in table
    # The files the run used, with their sha256 (record.json), and the zero reference.
    record = json.loads((clean_run / "record.json").read_text())
    assert record["inputs"] and all(i["sha256"] in text for i in record["inputs"])
    assert "inputs" in html.ids and "zero: Park" in text
    # Under a few MB for a 15-s run, and far under it.
    assert (clean_run / "report.html").stat().st_size < 1_500_000


def test_report_of_a_faulted_run_shows_the_fault_on_every_plot(fault_run):
    text, html = page(fault_run)
    assert "FAILED" in text and "fault" in html.ids
    fault = RunFolder(fault_run).report()["fault"]
    assert fault["cause"] == "tow_error" and fault["module"] == 4
    box = text[text.index('id="fault"'):text.index("</div>", text.index('id="fault"'))]
    assert "tow_error" in box and "module 4" in box.replace("<th>module</th><td>", "module ")
    fault_t = next(e["t"] for e in RunFolder(fault_run).events() if e["type"] == "fault")
    assert f"{fault_t:.3f} s" in box
    for plot in TIME_PLOTS:
        svg = text[text.index(f'id="{plot}"'):]
        svg = svg[:svg.index("</figure>")]
        axes = 3 if plot != "plot-guards" else 1
        markers = re.findall(rf'id="{plot}-fault-(\d)"', svg)
        assert sorted(markers) == [str(k) for k in range(axes)], plot
        # The label (text is drawn as paths; matplotlib keeps the string as a comment).
        assert "<!-- fault: tow_error -->" in svg


def test_loop_period_histogram_only_for_real_time_runs(clean_run, tmp_path):
    # The same folder as if it had run in real time (the flag in run_started): the page
    # gains the loop-period histogram; its caption gives the statistics.
    folder = tmp_path / "rt"
    shutil.copytree(clean_run, folder)
    lines = gzip.decompress((folder / "events.jsonl.gz").read_bytes()).decode().splitlines()
    lines = [line.replace('"virtual_time":true', '"virtual_time":false') for line in lines]
    (folder / "events.jsonl.gz").write_bytes(gzip.compress(("\n".join(lines) + "\n").encode()))
    write_html(folder)
    text, html = page(folder)
    assert html.plots == TIME_PLOTS + ["plot-loop-period"]
    assert "median 10.00 ms" in text


def test_a_killed_run_still_gets_a_report(clean_run, tmp_path):
    folder = tmp_path / "killed"
    shutil.copytree(clean_run, folder)
    text = gzip.decompress((folder / "events.jsonl.gz").read_bytes()).decode()
    (folder / "events.jsonl.gz").unlink()   # as an older run: plain, and torn
    junk = '{"t":0.5,"type":"setpoint","step":5}\n'     # a reading without joints
    (folder / "events.jsonl").write_text(junk + text[:len(text) // 2])     # torn mid-line
    (folder / "report.json").write_text(json.dumps({"sequence": "Op-safe", "status": "running",
                                                    "exit_code": None}))
    (folder / "report.html").unlink()
    result = CliRunner().invoke(app, ["report", str(folder)])
    assert result.exit_code == 0, result.output
    html_text, html = page(folder)
    assert "RUNNING" in html_text and "did not finish" in html_text
    assert "1 unreadable line(s)" in html_text
    assert html.plots == TIME_PLOTS


def test_report_of_a_refused_run(tmp_path):
    # A run refused by validation leaves report.json only: the page says why.
    folder = tmp_path / "refused"
    folder.mkdir()
    (folder / "report.json").write_text(json.dumps({
        "sequence": "bad", "status": "refused", "exit_code": 1, "message": "refused",
        "errors": [{"file": "bad.yaml", "line": 3, "column": 7, "message": "unknown pose"}]}))
    result = CliRunner().invoke(app, ["report", str(folder)])
    assert result.exit_code == 0, result.output
    text, html = page(folder)
    assert "REFUSED" in text and "bad.yaml:3:7: unknown pose" in text and html.plots == []


def test_report_command_errors_are_one_line(tmp_path):
    result = CliRunner().invoke(app, ["report", str(tmp_path / "nothing")])
    assert result.exit_code == 2
    assert result.output.strip().splitlines() == [f"error: {tmp_path / 'nothing'}: no such run folder"]
    result = CliRunner().invoke(app, ["report", str(tmp_path)])
    assert result.exit_code == 2 and "not a run folder" in result.output


def test_csv_export(clean_run, tmp_path):
    out = tmp_path / "csv"
    result = CliRunner().invoke(app, ["report", str(clean_run), "--csv", str(out)])
    assert result.exit_code == 0, result.output
    with open(out / "timeseries.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    log = RunFolder(clean_run).events()
    readings = [e for e in log if e["type"] in ("setpoint", "measurement")]
    assert len(rows) == len(readings)
    for name in JOINTS:
        for kind in ("planned_deg", "measured_deg", "planned_vel_deg_s", "measured_vel_deg_s",
                     "state"):
            assert f"{name}_{kind}" in rows[0]
    first_cycle = next(e for e in log if e["type"] == "setpoint")
    # a reading's time is when the joints answered (read_t; one here, no stall)
    row = next(r for r in rows if float(r["t_s"]) == first_cycle["read_t"])
    assert [float(row[f"{n}_planned_deg"]) for n in JOINTS] == first_cycle["planned_deg"]
    assert row["j1_state"] and row["streamed"] == "1"
    # The end-effector pose of the last reading is the checkpoint's.
    report = RunFolder(clean_run).report()
    reached = report["checkpoints"][0]["reached_position_mm"]
    last = rows[-1]
    assert [float(last[k]) for k in ("ee_x_mm", "ee_y_mm", "ee_z_mm")] == pytest.approx(
        reached, abs=0.01)
    with open(out / "steps.csv", newline="") as f:
        steps = list(csv.DictReader(f))
    assert [int(s["step"]) for s in steps] == list(range(1, 10))
    move = steps[4]
    assert float(move["j4_max_following_error_deg"]) == report["steps"][4][
        "max_following_error_deg"][3]


def test_junit_has_a_case_per_step_and_per_checkpoint_with_measured_values(clean_run):
    root = ET.parse(clean_run / "junit.xml").getroot()
    steps, checkpoints = root.findall("testsuite")
    assert len(steps.findall("testcase")) == 9 and steps.get("failures") == "0"
    # the measured values are the suite's properties, stepNN.<value> (junit-10.xsd allows
    # none on a test case: tests/test_junit_schema.py)
    props = {p.get("name"): p.get("value") for p in steps.iter("property")}
    report = RunFolder(clean_run).report()
    figures = report["steps"][4]
    assert float(props["step05.max_following_error_deg.j4"]) == \
        figures["max_following_error_deg"][3]
    assert float(props["step05.peak_measured_velocity_deg_s.j2"]) == \
        figures["peak_measured_velocity_deg_s"][1]
    assert float(props["step05.executed_duration_s"]) == pytest.approx(
        figures["executed_duration_s"], abs=1e-4)
    [case] = checkpoints.findall("testcase")
    assert case.get("classname").endswith(".checkpoints") and case.find("failure") is None
    [checkpoint] = report["checkpoints"]
    prefix = f"step{checkpoint['step']:02d}."
    props = {p.get("name").removeprefix(prefix): p.get("value")
             for p in checkpoints.iter("property")}
    assert float(props["position_error_mm"]) == checkpoint["position_error_mm"]
    assert float(props["position_tolerance_mm"]) == checkpoint["position_tolerance_mm"]
    assert props["reached_position_mm"].split() == [f"{x:g}" for x in
                                                    checkpoint["reached_position_mm"]]


def test_junit_of_a_faulted_run(fault_run):
    steps, checkpoints = ET.parse(fault_run / "junit.xml").getroot().findall("testsuite")
    cases = steps.findall("testcase")
    assert cases[4].find("failure") is not None and "TOW_ERROR" in cases[4].find(
        "failure").get("message")
    assert {p.get("name") for p in steps.iter("property")} >= {
        "step05.max_following_error_deg.j4", "step05.peak_measured_velocity_deg_s.j4"}
    assert checkpoints.find("testcase/skipped") is not None


def test_dry_run_report(tmp_path):
    out = tmp_path / "dry.html"
    result = CliRunner().invoke(app, ["validate", str(OPSAFE), "--report", str(out)])
    assert result.exit_code == 0, result.output
    assert f"report: {out}" in result.output
    text = out.read_text()
    html = Page(text)
    assert "Dry run report" in text and "dry run, virtual time, 100 Hz" in text
    assert html.plots == TIME_PLOTS and html.external == []
    result = CliRunner().invoke(app, ["validate", str(OPSAFE), "--report",
                                      str(tmp_path / "no" / "dir.html")])
    assert result.exit_code == 2 and "no directory" in result.output


def test_report_is_not_drawn_into_the_runs_outcome(tmp_path, monkeypatch):
    # A broken report is a warning: the run's exit code and files stand.
    def broken(*args, **kwargs):
        raise RuntimeError("plotting failed")

    monkeypatch.setattr("seqrun.report.write_html", broken)
    folder = tmp_path / "run"
    result = cli_run(folder)
    assert result.exit_code == 0
    assert "warning: report.html not written (RuntimeError: plotting failed)" in result.output
    assert (folder / "report.json").is_file() and not (folder / "report.html").exists()


def test_no_report_leaves_the_page_out_and_report_draws_it_later(tmp_path):
    folder = tmp_path / "run"
    result = CliRunner().invoke(app, ["run", str(ROOT / "sequences" / "totem.yaml"),
                                      "--virtual-time", "--yes", "--plain", "--no-report",
                                      "--log-dir", str(folder)])
    assert result.exit_code == 0, result.output
    assert (folder / "report.json").is_file() and not (folder / "report.html").exists()
    out = tmp_path / "elsewhere.html"
    result = CliRunner().invoke(app, ["report", str(folder), "--out", str(out)])
    assert result.exit_code == 0 and result.output.strip() == f"wrote {out}"
    assert Page(out.read_text()).plots == TIME_PLOTS


def test_loader_reads_the_series_in_time_order(clean_run):
    data = load_run(clean_run)
    s = Series.concatenate(list(data.readings()), data.dof)
    readings = [e for e in RunFolder(clean_run).events() if e["type"] in ("setpoint", "measurement")]
    assert np.all(np.diff(s.t) >= 0) and len(s) == len(readings) == data.reading_count
    assert data.arm is not None and data.arm.joint_names == JOINTS
    assert np.all(np.isnan(s.planned[~s.streamed])) and not np.any(np.isnan(s.planned[s.streamed]))
    assert np.all(s.state >= 0)


def test_decimation_keeps_the_envelope():
    t = np.linspace(0, 600, 60_000)
    y = np.sin(t) + (t > 300) * 5.0
    y[1234] = 40.0                                      # one spike must survive
    y[5000:5100] = np.nan                               # a gap stays a gap
    td, yd = decimate(t, y, 3000)
    assert len(td) <= 3000 and np.all(np.diff(td) > 0)
    assert np.nanmax(yd) == 40.0 and np.nanmin(yd) == pytest.approx(np.nanmin(y))
    assert np.any(np.isnan(yd))


def test_csv_cells_that_a_spreadsheet_would_run_are_neutralised(tmp_path):
    """Issue 23 (item 6): a step label from a sequence file is a cell of steps.csv; one
    starting with = + - @ is a formula to a spreadsheet. It gets a leading ', while
    negative numbers stay numbers."""
    from projecttree import make_project, write_sequence

    project = make_project(tmp_path / "p")
    seq = write_sequence(project, """\
        - include: startup.yaml
        - confirm: {prompt: "=HYPERLINK(\\"http://x\\")", label: "=HYPERLINK(1)"}
        - wait: {seconds: 0.1, label: "+cmd|' /C calc'!A0"}
        - wait: {seconds: 0.1, label: "@SUM(A1:A9)"}
        - wait: {seconds: 0.1, label: "-2+3"}
        - wait: {seconds: 0.1, label: "-1.5"}
    """)
    run = tmp_path / "run"
    result = CliRunner().invoke(app, ["run", str(seq), "--yes", "--virtual-time", "--plain",
                                      "--no-report", "--log-dir", str(run)])
    assert result.exit_code == 0, result.output
    out = tmp_path / "csv"
    assert CliRunner().invoke(app, ["report", str(run), "--csv", str(out)]).exit_code == 0
    with open(out / "steps.csv", newline="") as f:
        labels = [row["label"] for row in csv.DictReader(f)][-5:]
    assert labels == ["'=HYPERLINK(1)", "'+cmd|' /C calc'!A0", "'@SUM(A1:A9)", "'-2+3",
                      "-1.5"]
    with open(out / "timeseries.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    negative = [r["j4_measured_deg"] for r in rows if r["j4_measured_deg"].startswith("-")]
    assert negative and all(float(v) < 0 for v in negative)  # Park's j4 is -120.32
    from seqrun.report.csvout import neutralise

    assert [neutralise(c) for c in ("-0.5", "+2", "=1", "-inf", "-", "", 3.0)] == [
        "-0.5", "+2", "'=1", "'-inf", "'-", "", 3.0]
