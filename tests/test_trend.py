"""``seqrun trend`` (issue 40.3): values over a campaign's runs, drift, flaky runs.

Five real ``seqrun run --virtual-time`` runs of Op-safe (in process) into one runs folder:
the move up to Totem at four speeds (so its duration drifts), the fastest twice with the
same inputs, once with an injected ``--sim-fault`` (a flaky pair); plus a copy of the first
run stripped to what an older seqrun wrote. The CSV is held against each run's own
report.json, the drift against a recomputation, and the page is opened in Chromium.
"""

from __future__ import annotations

import csv
import io
import json
import os
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers the commands)
from projecttree import make_project
from seqrun.cli.app import app

#: The tests on the five runs (a minute on a busy machine) and the browser's.
slow = pytest.mark.slow
CHROMIUM = os.environ.get("SEQRUN_CHROMIUM") or shutil.which("chromium") or "/usr/bin/chromium"
UP = "velocity_scale: 0.5, label: Up to Totem"
#: (run folder, speed of the move up to Totem, --sim-fault)
RUNS = [("r1", "0.5", None), ("r2", "0.6", None), ("r3", "0.8", None),
        ("r4", "0.8", "4:tow_error@2"), ("r5", "0.9", None)]
OLD = "r0-old"


def cli(*args: str):
    result = CliRunner().invoke(app, list(args))
    assert result.exception is None or isinstance(result.exception, SystemExit), result.output
    return result


@pytest.fixture(scope="module")
def campaign(tmp_path_factory) -> Path:
    root = make_project(tmp_path_factory.mktemp("trend") / "campaign",
                        sequences=("startup.yaml", "opsafe.yaml"))
    sequence = root / "sequences" / "opsafe.yaml"
    text = sequence.read_text(encoding="utf-8")
    assert text.count(UP) == 1, "sequences/opsafe.yaml changed: update UP"
    for name, speed, fault in RUNS:
        sequence.write_text(text.replace(UP, UP.replace("0.5", speed)), encoding="utf-8")
        result = cli("run", str(sequence), "--virtual-time", "--yes", "--plain", "--no-report",
                     "--log-dir", str(root / "runs" / name),
                     *(("--sim-fault", fault) if fault else ()))
        assert result.exit_code == (3 if fault else 0), result.output
    _old_format_copy(root / "runs" / "r1", root / "runs" / OLD)
    return root


def _old_format_copy(source: Path, target: Path) -> None:
    """What an older seqrun left: no record.json, no inputs, no start, no lowest heights,
    no checkpoints list, steps without their tracking and checkpoint figures."""
    target.mkdir()
    report = json.loads((source / "report.json").read_text(encoding="utf-8"))
    for key in ("start", "end", "inputs", "min_heights_mm", "checkpoints", "faults", "host"):
        report.pop(key)
    for step in report["steps"]:
        for key in ("max_following_error_deg", "position_error_mm", "position_tolerance_mm",
                    "final_error_deg", "peak_measured_velocity_deg_s"):
            step.pop(key, None)
    (target / "report.json").write_text(json.dumps(report), encoding="utf-8")


def reports(root: Path) -> dict[str, dict]:
    return {p.name: json.loads((p / "report.json").read_text(encoding="utf-8"))
            for p in (root / "runs").iterdir() if (p / "report.json").is_file()}


@pytest.fixture(scope="module")
def trend_out(campaign, tmp_path_factory):
    out = tmp_path_factory.mktemp("out")
    # No RUNS argument: the campaign's runs folder, as `seqrun runs` finds it.
    result = cli("trend", "--project", str(campaign), "--out", str(out / "trend.html"),
                 "--csv", str(out / "trend.csv"))
    assert result.exit_code == 0, result.output
    rows = list(csv.DictReader(io.StringIO((out / "trend.csv").read_text(encoding="utf-8"))))
    return result.output, rows, out / "trend.html"


def series_rows(rows: list[dict], metric: str, step: str, item: str = "") -> list[dict]:
    return [r for r in rows if r["metric"] == metric and r["step"] == step
            and r["item"] == item]


@slow
def test_runs_are_in_the_order_they_started_the_old_one_first(trend_out, campaign):
    _, rows, _ = trend_out
    order = [r["run"] for r in series_rows(rows, "duration_s", "run")]
    started = sorted((rep["start"], name) for name, rep in reports(campaign).items()
                     if "start" in rep)
    assert order == [OLD] + [name for _, name in started]
    assert order == [OLD, "r1", "r2", "r3", "r4", "r5"]


@slow
def test_csv_values_are_the_runs_report_json_figures(trend_out, campaign):
    _, rows, _ = trend_out
    runs = reports(campaign)
    checked = 0
    for row in rows:
        if row["run"] == OLD:
            continue
        report = runs[row["run"]]
        assert row["run_status"] == report["status"]
        steps = {str(s["number"]): s for s in report["steps"]}
        if row["step"] == "run":
            expected = (report["duration_s"] if row["metric"] == "duration_s"
                        else report["min_heights_mm"][row["item"]])
        elif steps[row["step"]]["status"] == "pending":
            assert row["value"] == "not run", row   # the faulted run never got there
            assert row["limit"] == "" and row["drift_from_first"] == "", row
            continue
        else:
            step = steps[row["step"]]
            errors = step.get("max_following_error_deg")
            expected = {"duration_s": step.get("duration_s"),
                        "checkpoint_error_mm": step.get("position_error_mm"),
                        "following_error_deg": max(errors) if errors else None,
                        "peak_current_a": None}[row["metric"]]
        if expected is None:
            assert row["value"] == "not recorded", row
        else:
            assert float(row["value"]) == expected, row
            checked += 1
    assert checked > 60
    # The limits are the runs' own: the checkpoint's tolerance, the guard's line.
    checkpoint = series_rows(rows, "checkpoint_error_mm", "9")
    assert {r["limit"] for r in checkpoint if r["run"] != OLD and r["value"] != "not run"} \
        == {"7.0"}
    wrist = series_rows(rows, "clearance_mm", "run", "desk:wrist")
    assert {r["limit"] for r in wrist if r["run"] != OLD} == {"10.0"}
    margin = next(r for r in wrist if r["run"] == "r1")
    assert float(margin["margin_to_limit"]) == pytest.approx(float(margin["value"]) - 10.0)


@slow
def test_drift_is_each_value_minus_the_first_recorded(trend_out):
    output, rows, _ = trend_out
    move = series_rows(rows, "duration_s", "5")
    values = [float(r["value"]) for r in move]
    assert values[0] == values[1] and values[-1] < values[2] < values[1]   # faster: shorter
    for row, value in zip(move, values):
        assert float(row["drift_from_first"]) == pytest.approx(value - values[0], abs=1e-9)
    line = next(x for x in output.splitlines() if "step 5 " in x and "duration_s:" in x)
    assert f"drift {values[-1] - values[0]:+g}" in line
    assert f"first {values[0]:g}, last {values[-1]:g}" in line
    # Every series: drift is value minus the series' first recorded value.
    for key in {(r["metric"], r["step"], r["item"]) for r in rows}:
        series = series_rows(rows, *key)
        recorded = [r for r in series if r["value"] not in ("not recorded", "not run")]
        for r in recorded:
            assert float(r["drift_from_first"]) == pytest.approx(
                float(r["value"]) - float(recorded[0]["value"]), abs=1e-9)


@slow
def test_the_same_inputs_with_another_verdict_are_flaky(trend_out, campaign):
    output, rows, page = trend_out
    flaky = [x for x in output.splitlines() if x.startswith("FLAKY")]
    assert len(flaky) == 1, output
    assert "r3 passed" in flaky[0] and "r4 failed (--sim-fault 4:tow_error@2)" in flaky[0]
    assert "r1" not in flaky[0] and "r5" not in flaky[0]
    inputs = {r["run"]: r["inputs_sha256"] for r in series_rows(rows, "duration_s", "run")}
    assert inputs["r3"] == inputs["r4"] != inputs["r5"]
    assert inputs[OLD] == "not recorded"
    assert 'id="flaky"' in page.read_text(encoding="utf-8")
    assert "1 flaky group(s)" in output


@slow
def test_an_older_run_folder_reads_as_not_recorded(trend_out):
    output, rows, _ = trend_out
    old = [r for r in rows if r["run"] == OLD]
    assert old and all(r["start"] == "not recorded" for r in old)
    by_metric: dict[str, set[str]] = {}
    for r in old:
        by_metric.setdefault(r["metric"], set()).add(r["value"])
    assert by_metric["checkpoint_error_mm"] == {"not recorded"}
    assert by_metric["following_error_deg"] == {"not recorded"}
    assert by_metric["clearance_mm"] == {"not recorded"}
    assert "not recorded" not in by_metric["duration_s"]     # it kept its durations
    assert "Traceback" not in output


@slow
def test_a_metric_no_run_recorded_is_never_filled_in(trend_out):
    output, rows, _ = trend_out
    currents = [r for r in rows if r["metric"] == "peak_current_a"]
    assert currents and {r["value"] for r in currents} <= {"not recorded", "not run"}
    assert "peak_current_a: not recorded in 6 run(s)" in output


@slow
def test_filters_and_a_limit_of_ones_own(campaign, tmp_path):
    result = cli("trend", str(campaign / "runs"), "--sequence", "opsafe", "--step", "5",
                 "--metric", "duration_s", "--limit", "9", "--csv", str(tmp_path / "t.csv"),
                 "--out", str(tmp_path / "t.html"))
    assert result.exit_code == 0, result.output
    rows = list(csv.DictReader(io.StringIO((tmp_path / "t.csv").read_text(encoding="utf-8"))))
    assert {(r["metric"], r["step"]) for r in rows} == {("duration_s", "5")}
    assert {r["limit"] for r in rows} == {"9.0"} and {r["limit_source"] for r in rows} == {
        "--limit"}
    for r in rows:
        assert float(r["margin_to_limit"]) == pytest.approx(9.0 - float(r["value"]))
    assert len([x for x in result.output.splitlines() if " · " in x]) == 1


@pytest.mark.parametrize("args, message", [
    (["--metric", "speed"], "--metric speed: not a metric"),
    (["--limit", "3"], "--limit: name the --metric"),
    (["--sequence", "Nope"], "--sequence Nope: no run of it"),
    (["--step", "77"], "--step 77: no step"),
])
@slow
def test_bad_arguments_are_one_line(campaign, args, message):
    result = cli("trend", str(campaign / "runs"), *args)
    assert result.exit_code == 2
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and message in lines[0], lines


def test_a_folder_that_does_not_exist_is_one_line(tmp_path):
    result = cli("trend", str(tmp_path / "nothing"))
    assert result.exit_code == 2
    assert result.output.strip() == f"error: {tmp_path / 'nothing'}: no such folder"


@slow
def test_an_unreadable_report_is_named_and_the_others_still_trend(campaign, tmp_path):
    runs = tmp_path / "runs"
    shutil.copytree(campaign / "runs" / "r1", runs / "r1")
    (runs / "broken").mkdir()
    (runs / "broken" / "report.json").write_text("{", encoding="utf-8")
    result = cli("trend", str(runs))
    assert result.exit_code == 0, result.output
    assert f"warning: {runs / 'broken'}: report.json unreadable" in result.output
    assert (runs / "trend.html").is_file()
    assert "over 1 run(s)" in result.output


# --------------------------------------------------------------------------- the browser
@pytest.fixture(scope="session")
def browser_type_launch_args(browser_type_launch_args):
    assert Path(CHROMIUM).is_file(), (
        f"Chromium not found at {CHROMIUM}: apt-get install chromium (or set SEQRUN_CHROMIUM)")
    return {**browser_type_launch_args, "executable_path": CHROMIUM, "headless": True,
            "args": ["--no-sandbox", "--headless", "--disable-gpu",
                     "--disable-background-networking", "--disable-component-update",
                     "--no-first-run"]}


@slow
def test_the_page_renders_in_chromium_offline_without_errors(page, trend_out):
    _, rows, html = trend_out
    errors: list[str] = []
    requests: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("request", lambda r: requests.append(r.url))
    page.set_viewport_size({"width": 1200, "height": 900})
    page.goto(html.as_uri())
    assert errors == [] and requests == [html.as_uri()]
    assert page.title() == "Trends"
    keys = {(r["metric"], r["step"], r["label"], r["item"]) for r in rows}
    drawn = {k for k in keys if any(r["value"] not in ("not recorded", "not run")
                                    for r in rows if (r["metric"], r["step"], r["label"],
                                                      r["item"]) == k)}
    assert page.locator("section.series").count() == len(keys)
    assert page.locator("figure.plot svg").count() == len(drawn)
    box = page.locator("figure.plot svg").first.bounding_box()
    assert box and box["width"] > 500 and box["height"] > 100
    assert page.locator("#flaky tr.flaky").count() == 1
    assert page.locator("#runs tr").count() == 1 + 6


def test_a_folder_without_runs_says_so(tmp_path):
    result = cli("trend", str(tmp_path))
    assert result.exit_code == 0
    assert result.output.strip() == f"no runs in {tmp_path}"
    assert not (tmp_path / "trend.html").exists()


# --------------------------------------------------------------------------- odd folders
def _folder(root: Path, name: str, report: object, record: object = None) -> Path:
    folder = root / name
    folder.mkdir(parents=True)
    (folder / "report.json").write_text(json.dumps(report), encoding="utf-8")
    if record is not None:
        (folder / "record.json").write_text(json.dumps(record), encoding="utf-8")
    return folder


def test_odd_and_older_report_fields_are_not_recorded_never_a_traceback(tmp_path):
    runs = tmp_path / "runs"
    _folder(runs, "a", {"status": "passed"})
    _folder(runs, "b", {"sequence": 5, "steps": 7, "inputs": "x", "min_heights_mm": [1],
                        "status": 3, "start": 12, "duration_s": "12", "faults": "no"},
            record=["not", "a", "record"])
    _folder(runs, "c", {"sequence": "S", "start": "2026-01-01T00:00:00", "status": "failed",
                        "steps": [1, {"number": True}, {
                            "number": 2, "kind": "checkpoint", "label": 5,
                            "position_error_mm": "0.1", "position_tolerance_mm": None}]})
    _folder(runs, "d", [])
    result = cli("trend", str(runs), "--csv", str(tmp_path / "t.csv"))
    assert result.exit_code == 0, result.output
    assert f"warning: {runs / 'd'}: report.json unreadable" in result.output
    rows = list(csv.DictReader(io.StringIO((tmp_path / "t.csv").read_text(encoding="utf-8"))))
    checkpoint = [r for r in rows if r["metric"] == "checkpoint_error_mm"]
    assert [(r["sequence"], r["step"], r["label"], r["value"], r["limit"])
            for r in checkpoint] == [("S", "2", "5", "not recorded", "")]
    assert {r["value"] for r in rows if r["run"] in ("a", "b")} == {"not recorded"}
    assert "over 3 run(s)" in result.output


def test_flaky_needs_the_same_inputs_and_two_verdicts(tmp_path):
    def record(*hashes: str) -> dict:
        return {"inputs": [{"copy": f"inputs/{h}.yaml", "sha256": h * 64} for h in hashes]}

    runs = tmp_path / "runs"
    for name, start, status, inputs in [("1", "01", "passed", ("a", "b")),
                                        ("2", "02", "failed", ("b", "a")),   # same set
                                        ("3", "03", "failed", ("a", "c")),
                                        ("4", "04", "running", ("a", "c")),  # no verdict yet
                                        ("5", "05", "passed", ("c",))]:
        _folder(runs, name, {"sequence": "S", "start": f"2026-01-{start}", "status": status,
                             "duration_s": 1.0, "steps": []}, record=record(*inputs))
    result = cli("trend", str(runs), "--out", str(tmp_path / "t.html"))
    assert result.exit_code == 0, result.output
    flaky = [x for x in result.output.splitlines() if x.startswith("FLAKY")]
    assert len(flaky) == 1 and "1 passed, 1 failed: 1 passed, 2 failed" in flaky[0], flaky
    page = (tmp_path / "t.html").read_text(encoding="utf-8")
    assert page.count('<tr class="flaky">') == 1


def test_a_run_of_several_arms_is_a_run_per_arm(tmp_path):
    run = tmp_path / "runs" / "both"
    for arm, duration in (("left", 2.0), ("right", 3.0)):
        _folder(run, arm, {"sequence": "Two", "start": "2026-01-01", "status": "passed",
                           "duration_s": duration, "steps": []})
    (run / "arms.json").write_text(json.dumps({"sequence": "Two"}), encoding="utf-8")
    result = cli("trend", str(tmp_path / "runs"), "--csv", str(tmp_path / "t.csv"))
    assert result.exit_code == 0, result.output
    rows = list(csv.DictReader(io.StringIO((tmp_path / "t.csv").read_text(encoding="utf-8"))))
    assert [(r["sequence"], r["run"], r["value"]) for r in rows] == [
        ("Two (arm left)", "both/left", "2.0"), ("Two (arm right)", "both/right", "3.0")]
    assert (tmp_path / "runs" / "trend.html").is_file()
