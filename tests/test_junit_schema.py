"""junit.xml is valid JUnit for strict CI tools, and CTRF JSON lies beside it (issue 41.6).

The schema is tests/data/junit-10.xsd: the constraints of Jenkins xunit's junit-10.xsd
(testsuites/testsuite/testcase/properties/property/skipped/error/failure/system-out/
system-err and their attributes: ``errors`` required on a testsuite, no ``file`` attribute
and no ``<properties>`` on a testcase), written out from that schema's structure because
the test machine cannot download it. ``xmlschema`` (the test extra) validates against it.
The CTRF checks are those of ctrf.io's report format: ``reportFormat``, ``specVersion``,
``results.tool.name``, a summary that counts the tests by status, a name, a status and a
duration in ms per test.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import xmlschema
from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers the commands)
from projecttree import ROOT
from runfolder import RunFolder
from test_report import clean_run, fault_run  # noqa: F401  (the same two runs)
from seqrun.cli.app import app

SCHEMA = xmlschema.XMLSchema(str(ROOT / "tests" / "data" / "junit-10.xsd"))
OPSAFE = ROOT / "sequences" / "opsafe.yaml"


def errors_of(path: Path) -> list[str]:
    return [f"{e.path}: {e.reason}" for e in SCHEMA.iter_errors(str(path))]


def test_the_schema_refuses_what_strict_tools_refuse(tmp_path):
    """The schema itself: the three faults junit.xml had (and a valid document passes)."""
    bad = tmp_path / "bad.xml"
    bad.write_text('<testsuites><testsuite name="s" tests="1" failures="0">'
                   '<testcase name="c" file="a.yaml"><properties><property name="p" value="1"/>'
                   "</properties></testcase></testsuite></testsuites>")
    reasons = " | ".join(errors_of(bad))
    assert "errors" in reasons and "file" in reasons and "properties" in reasons, reasons
    good = tmp_path / "good.xml"
    good.write_text('<testsuites><testsuite name="s" tests="1" failures="0" errors="0" '
                    'time="1.500"><properties><property name="p" value="1"/></properties>'
                    '<testcase name="c" time="0.1"><system-out>x</system-out></testcase>'
                    "</testsuite></testsuites>")
    assert errors_of(good) == []


@pytest.mark.parametrize("which", ["clean_run", "fault_run"])
def test_a_runs_junit_xml_is_valid_junit_10(which, request):
    folder = request.getfixturevalue(which)
    assert errors_of(folder / "junit.xml") == []


def test_measured_values_are_the_suites_properties(clean_run):
    steps, checkpoints = ET.parse(clean_run / "junit.xml").getroot().findall("testsuite")
    assert steps.get("errors") == "0" and steps.get("failures") == "0"
    assert all(case.find("properties") is None for case in steps.iter("testcase"))
    props = {p.get("name"): p.get("value") for p in steps.find("properties")}
    report = RunFolder(clean_run).report()
    move = report["steps"][4]
    assert float(props["step05.max_following_error_deg.j4"]) == \
        move["max_following_error_deg"][3]
    assert float(props["step05.executed_duration_s"]) == pytest.approx(
        move["executed_duration_s"], abs=1e-4)
    [checkpoint] = report["checkpoints"]
    cp = {p.get("name"): p.get("value") for p in checkpoints.find("properties")}
    number = checkpoint["step"]
    assert float(cp[f"step{number:02d}.position_error_mm"]) == checkpoint["position_error_mm"]
    # each step's place in the sequence, where a test case may carry it
    first = steps.find("testcase")
    assert first.find("system-out").text == f"step at {report['steps'][0]['location']}"


def ctrf_of(path: Path) -> dict:
    """The ``results`` of a CTRF report, its format checked."""
    document = json.loads(path.read_text(encoding="utf-8"))
    assert document["reportFormat"] == "CTRF"
    assert document["specVersion"].count(".") == 2
    results = document["results"]
    assert results["tool"]["name"] == "seqrun"
    summary, tests = results["summary"], results["tests"]
    assert summary["tests"] == len(tests)
    for status in ("passed", "failed", "skipped", "pending", "other"):
        assert summary[status] == sum(t["status"] == status for t in tests), status
    assert isinstance(summary["start"], int) and summary["stop"] >= summary["start"]
    for test in tests:
        assert isinstance(test["name"], str) and test["name"]
        assert test["status"] in ("passed", "failed", "skipped", "pending", "other")
        assert isinstance(test["duration"], int) and test["duration"] >= 0
    return results


def test_ctrf_lies_beside_a_runs_junit_with_the_same_tests(clean_run, fault_run):
    results = ctrf_of(clean_run / "junit.ctrf.json")
    steps = ET.parse(clean_run / "junit.xml").getroot().find("testsuite")
    assert [t["name"] for t in results["tests"]] == [c.get("name") for c in
                                                     steps.iter("testcase")]
    assert results["summary"]["passed"] == len(results["tests"]) == 9
    report = RunFolder(clean_run).report()
    assert results["tests"][4]["extra"]["max_following_error_deg.j4"] == \
        f'{report["steps"][4]["max_following_error_deg"][3]:g}'
    assert all(t["filePath"].endswith(".yaml") and t["line"] > 0 for t in results["tests"])
    faulted = ctrf_of(fault_run / "junit.ctrf.json")
    [failed] = [t for t in faulted["tests"] if t["status"] == "failed"]
    assert "TOW_ERROR" in failed["message"]
    assert faulted["summary"]["failed"] == 1 and faulted["extra"]["exit_code"] == 3


def test_validate_junit_is_valid_and_has_ctrf_beside_it(tmp_path):
    target = tmp_path / "out" / "validate.xml"
    bad = ROOT / "tests" / "data" / "bad" / "out_of_limit.yaml"
    result = CliRunner().invoke(app, ["validate", "--static", str(OPSAFE), str(bad),
                                      "--junit", str(target)])
    assert result.exit_code == 1, result.output
    assert errors_of(target) == []
    suite = ET.parse(target).getroot().find("testsuite")
    assert (suite.get("tests"), suite.get("failures"), suite.get("errors")) == ("2", "1", "0")
    tests = ctrf_of(tmp_path / "out" / "validate.ctrf.json")["tests"]
    assert [t["status"] for t in tests] == ["passed", "failed"]
    assert "outside its limits" in tests[1]["message"]
