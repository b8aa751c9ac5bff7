"""Requirements (issue 40.2): ``verifies``/``tags`` on any step, the campaign's
requirements.csv checked by ``seqrun validate``, the requirements in report.json, junit.xml
and report.html, and the requirement matrix of ``seqrun report --requirements``."""

from __future__ import annotations

import csv
import io
import json
import re
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import xmlschema
from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers the commands)
from projecttree import ROOT, make_project, write_sequence
from seqrun.cli.app import app
from seqrun.errors import SequenceInvalid
from seqrun.sequence.loader import load_sequence
from seqrun.service.records import input_sources
from simrun import run_on_sim

UP = "- reset\n- home\n- set_limits\n"  # lines 4-6
REQUIREMENTS = ("id,text,method\n"
                "REQ-1,The arm reaches Op-safe,test\n"
                "REQ-2,The tool stays above the table,test\n"
                "REQ-3,Nobody verifies this one,inspection\n")
JUNIT = xmlschema.XMLSchema(str(ROOT / "tests" / "data" / "junit-10.xsd"))


@pytest.fixture
def project(tmp_path: Path) -> Path:
    root = make_project(tmp_path / "campaign")
    (root / "requirements.csv").write_text(REQUIREMENTS, encoding="utf-8")
    return root


def cli(*args: str):
    result = CliRunner().invoke(app, list(args))
    assert result.exception is None or isinstance(result.exception, SystemExit), result.output
    return result


# --------------------------------------------------------------------------- the keys
def test_verifies_and_tags_are_accepted_on_a_move_and_kept_on_the_step(project):
    path = write_sequence(project, UP + "- move: {pose: opsafe, verifies: [REQ-1], "
                                        "tags: [capture, smoke]}\n")
    step = load_sequence(path).steps[3]
    assert step.params.verifies == ["REQ-1"] and step.params.tags == ["capture", "smoke"]


@pytest.mark.parametrize("text, where, message", [
    ("- move: {pose: opsafe, verifies: REQ-1}\n", "7:34", "list"),
    ("- move: {pose: opsafe, tags: [12]}\n", "7:31", "expected text, got 12"),
    ("- move: {pose: opsafe, verifies: [REQ 1]}\n", "7:35", "pattern"),
    ("- include: {file: other.yaml, verifies: [REQ-1]}\n", "7:", "put verifies on those steps"),
])
def test_verifies_and_tags_of_a_wrong_type_are_refused_at_their_place(project, text, where,
                                                                       message):
    write_sequence(project, "- reset\n", "other.yaml")
    path = write_sequence(project, UP + text)
    with pytest.raises(SequenceInvalid) as caught:
        load_sequence(path)
    errors = [str(e) for e in caught.value.errors]
    assert any(f"s.yaml:{where}" in e and message in e for e in errors), errors


# --------------------------------------------------------------------------- validate
def test_validate_notes_an_id_the_requirements_csv_lacks(project):
    path = write_sequence(project, UP + "- move: {pose: opsafe, verifies: [REQ-1, REQ-9]}\n")
    result = cli("validate", str(path), "--static")
    assert result.exit_code == 0, result.output
    assert "s.yaml:7:42: note: requirement 'REQ-9' is not in" in result.output
    assert "'REQ-1' is not in" not in result.output


def test_validate_of_the_campaign_notes_unverified_requirements_and_bad_rows(project):
    (project / "requirements.csv").write_text(REQUIREMENTS + "REQ 4,bad id,test\nREQ-5,two\n",
                                              encoding="utf-8")
    for name in [p.name for p in (project / "sequences").iterdir()]:
        (project / "sequences" / name).unlink()
    write_sequence(project, UP + "- move: {pose: opsafe, verifies: [REQ-1]}\n"
                                 "- check: {that: 'tool.z_mm > 40', verifies: [REQ-2]}\n")
    result = cli("validate", str(project), "--static")
    assert result.exit_code == 0, result.output   # notes, not errors
    csv_path = (project / "requirements.csv").resolve()
    assert f"{csv_path}:4: requirement 'REQ-3' is verified by no sequence" in result.output
    assert f"{csv_path}:5: 'REQ 4' is not a requirement id" in result.output
    assert f"{csv_path}:6: 2 column(s), expected 3 (id,text,method)" in result.output
    assert "'REQ-1' is verified by no sequence" not in result.output
    assert "'REQ-2' is verified by no sequence" not in result.output


# --------------------------------------------------------------------------- a run's files
def _run(project: Path, tmp_path: Path, name: str, last: str):
    write_sequence(project, UP + "- move: {pose: opsafe, verifies: [REQ-1], tags: [smoke]}\n"
                   + last, f"{name}.yaml")
    return run_on_sim(name, tmp_path / name, root=project, html_report=True).outcome


PASSING = "- check: {that: 'tool.z_mm > 40', verifies: [REQ-2, REQ-1]}\n"
FAILING = "- check: {that: 'tool.z_mm > 40000', verifies: [REQ-2]}\n"


def test_report_json_junit_and_html_carry_the_requirements_of_a_passing_run(project, tmp_path):
    outcome = _run(project, tmp_path, "good", PASSING)
    assert outcome.result.exit_code == 0, outcome.result.message
    folder = tmp_path / "good" / "run"
    report = json.loads((folder / "report.json").read_text(encoding="utf-8"))
    assert report["requirements"] == {"REQ-1": "passed", "REQ-2": "passed"}
    move = report["steps"][3]
    assert move["verifies"] == ["REQ-1"] and move["tags"] == ["smoke"]
    assert "verifies" not in report["steps"][0]
    junit = folder / "junit.xml"
    assert [f"{e.path}: {e.reason}" for e in JUNIT.iter_errors(str(junit))] == []
    properties = {p.get("name"): p.get("value")
                  for p in ET.parse(junit).getroot().iter("property")}
    assert properties["step04.verifies"] == "REQ-1" and properties["step04.tags"] == "smoke"
    assert properties["step05.verifies"] == "REQ-2 REQ-1"
    ctrf = json.loads((folder / "junit.ctrf.json").read_text(encoding="utf-8"))
    assert ctrf["results"]["tests"][3]["extra"]["verifies"] == ["REQ-1"]
    html = (folder / "report.html").read_text(encoding="utf-8")
    assert 'data-step="4" data-figure="verifies">REQ-1<' in html
    assert 'data-step="4" data-figure="tags">smoke<' in html


def test_a_run_keeps_the_campaigns_requirements_csv_with_its_inputs(project):
    path = write_sequence(project, UP)
    kept = dict(input_sources(load_sequence(path)))
    assert kept[project / "requirements.csv"] == REQUIREMENTS.encode()


def test_a_failed_check_fails_its_requirement_and_leaves_the_others_passed(project, tmp_path):
    outcome = _run(project, tmp_path, "bad", FAILING)
    assert outcome.result.exit_code == 3
    folder = tmp_path / "bad" / "run"
    report = json.loads((folder / "report.json").read_text(encoding="utf-8"))
    assert report["requirements"] == {"REQ-1": "passed", "REQ-2": "failed"}
    assert JUNIT.is_valid(str(folder / "junit.xml"))


# --------------------------------------------------------------------------- the matrix
def test_the_matrix_of_three_runs_including_an_old_one(project, tmp_path):
    _run(project, tmp_path, "good", PASSING)
    _run(project, tmp_path, "bad", FAILING)
    runs = tmp_path / "runs"
    runs.mkdir()
    good = shutil.copytree(tmp_path / "good" / "run", runs / "20261128-090000-good")
    bad = shutil.copytree(tmp_path / "bad" / "run", runs / "20261128-100000-bad")
    old = shutil.copytree(good, runs / "20261101-080000-old")   # as an older seqrun wrote it
    report = json.loads((old / "report.json").read_text(encoding="utf-8"))
    del report["requirements"]
    for step in report["steps"]:
        step.pop("verifies", None)
        step.pop("tags", None)
    report["start"] = "2026-11-01T08:00:00+00:00"
    (old / "report.json").write_text(json.dumps(report), encoding="utf-8")
    # The requirements come from the campaign the runs recorded (``seqrun run`` writes it).
    (bad / "record.json").write_text(json.dumps({"campaign": str(project)}), encoding="utf-8")
    html, table = tmp_path / "out" / "matrix.html", tmp_path / "out" / "matrix.csv"
    result = cli("report", "--requirements", str(good), str(bad), str(old),
                 "--out", str(html), "--csv", str(table))
    assert result.exit_code == 0, result.output
    rows = list(csv.reader(io.StringIO(table.read_text(encoding="utf-8"))))
    order = sorted([good.name, bad.name, old.name],
                   key=lambda n: {good.name: 2, bad.name: 3, old.name: 1}[n])
    assert rows[0] == ["id", "text", "method", *order]
    by_id = {row[0]: dict(zip(rows[0], row)) for row in rows[1:]}
    assert set(by_id) == {"REQ-1", "REQ-2", "REQ-3"}
    assert by_id["REQ-2"][good.name] == "passed" and by_id["REQ-2"][bad.name] == "failed"
    assert by_id["REQ-1"][bad.name] == "passed"
    assert {by_id[r][old.name] for r in by_id} == {"not run"}
    assert {by_id["REQ-3"][n] for n in order} == {"not run"}   # listed though none verifies it
    assert by_id["REQ-3"]["method"] == "inspection"
    page = html.read_text(encoding="utf-8")
    assert "<script" not in page and "<link" not in page
    assert (f'<td class="cell failed" data-requirement="REQ-2" data-run="{bad.name}">failed'
            in page)
    assert f'data-requirement="REQ-3" data-run="{good.name}">not run' in page


def test_a_campaign_of_two_arms_counts_the_requirements_its_arms_verify(tmp_path, monkeypatch):
    from twoarmskit import copy_example

    folder = copy_example(tmp_path, monkeypatch)
    (folder / "requirements.csv").write_text("id,text,method\nREQ-A,A holds,test\n"
                                             "REQ-B,B approaches,test\n", encoding="utf-8")
    path = folder / "sequences" / "hold_and_approach.yaml"
    text = path.read_text(encoding="utf-8")
    old = "label: A up to Totem}"
    assert text.count(old) == 1
    path.write_text(text.replace(old, "label: A up to Totem, verifies: [REQ-A, REQ-X]}"),
                    encoding="utf-8")
    result = cli("validate", str(folder), "--static")
    # (the example's paths_cross.yaml is invalid on purpose: its arms collide)
    assert re.search(r"hold_and_approach\.yaml +valid ", result.output), result.output
    assert "requirement 'REQ-B' is verified by no sequence" in result.output
    assert "'REQ-A' is verified by no sequence" not in result.output
    assert "hold_and_approach.yaml:18:" in result.output and "'REQ-X' is not in" in result.output


def test_the_dry_run_sums_up_the_requirements_as_a_run_does(project):
    from seqrun.service.checking import check_sequence

    path = write_sequence(project, UP + "- move: {pose: opsafe, verifies: [REQ-1]}\n"
                          + FAILING)
    check = check_sequence(path)
    assert check.dry_run is not None
    assert check.dry_run.as_dict()["requirements"] == {"REQ-1": "passed", "REQ-2": "failed"}
