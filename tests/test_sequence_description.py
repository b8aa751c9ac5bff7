"""A sequence needs no ``description:`` (issue 44, item 5): a two-line test file validates
and runs; the report shows the name alone; the JSON Schema does not require it."""

from __future__ import annotations

import json

from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers the commands)
from projecttree import ROOT, make_project
from seqrun.cli.app import app
from seqrun.sequence.loader import load_sequence

TWO_LINES = "name: Nudge\nsteps: [{include: startup.yaml}, {move: {joints: {j1: 2}}}]\n"


def test_a_sequence_without_a_description_validates_and_runs(tmp_path, monkeypatch):
    monkeypatch.setenv("SEQRUN_STATE_DIR", str(tmp_path / "state"))
    project = make_project(tmp_path / "camp")
    path = project / "sequences" / "nudge.yaml"
    path.write_text(TWO_LINES)
    loaded = load_sequence(path)
    assert (loaded.name, loaded.description) == ("Nudge", "")
    result = CliRunner().invoke(app, ["validate", str(path)])
    assert result.exit_code == 0, result.output
    assert "description" not in result.output
    run = tmp_path / "run"
    result = CliRunner().invoke(app, ["run", str(path), "--virtual-time", "--yes", "--plain",
                                      "--no-report", "--log-dir", str(run)])
    assert result.exit_code == 0, result.output
    assert json.loads((run / "report.json").read_text())["sequence"] == "Nudge"


def test_the_schema_does_not_require_a_description():
    schema = json.loads((ROOT / "docs" / "schema" / "sequence.schema.json").read_text())
    assert schema["required"] == ["name", "steps"]
    assert "optional" in schema["properties"]["description"]["description"]
    result = CliRunner().invoke(app, ["schema"])
    assert result.exit_code == 0
    assert json.loads(result.output)["required"] == ["name", "steps"]
