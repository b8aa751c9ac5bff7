"""``seqrun validate``'s exit codes mean what ``seqrun run``'s mean: a dry run aborted by a
rehearsed ``--sim-fault`` exits 3 (aborted by a fault, as the run would), 1 is only ever
"invalid" (README "Exit codes")."""

from __future__ import annotations

from typer.testing import CliRunner

import seqrun.cli.validate  # noqa: F401  (registers `validate`)
from projecttree import ROOT
from seqrun.cli.app import app
from seqrun.defaults import EXIT_FAULT, EXIT_INVALID, EXIT_OK

runner = CliRunner()
OPSAFE = ROOT / "sequences" / "opsafe.yaml"


def validate(*args: str):
    result = runner.invoke(app, ["validate", *map(str, args)])
    assert "Traceback" not in result.output
    return result


def test_a_rehearsed_fault_is_exit_3_as_in_run():
    result = validate("--sim-fault", "4:tow_error@3", OPSAFE)
    assert result.exit_code == EXIT_FAULT, result.output
    assert "FAILED" in result.output


def test_a_rehearsed_fault_in_json_is_exit_3():
    result = validate("--json", "--sim-fault", "4:tow_error@3", OPSAFE)
    assert result.exit_code == EXIT_FAULT, result.output
    assert '"valid": false' in result.output


def test_a_fault_that_never_comes_leaves_exit_0():
    # the fault is due after the sequence ended: nothing to rehearse, the file is valid
    result = validate("--sim-fault", "4:tow_error@500", OPSAFE)
    assert result.exit_code == EXIT_OK, result.output


def test_an_invalid_file_stays_exit_1_with_a_rehearsed_fault():
    bad = ROOT / "tests" / "data" / "bad" / "velocity_above_max.yaml"
    result = validate("--sim-fault", "4:tow_error@3", bad)
    assert result.exit_code == EXIT_INVALID, result.output


def test_a_campaign_with_a_rehearsed_fault_is_exit_3():
    result = validate("--sim-fault", "4:tow_error@3", OPSAFE, ROOT / "sequences" / "totem.yaml")
    assert result.exit_code == EXIT_FAULT, result.output
