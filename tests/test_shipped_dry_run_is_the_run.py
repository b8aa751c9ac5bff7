"""Every shipped sequence: ``seqrun validate --json`` (the dry run) and ``seqrun run
--virtual-time`` agree on the verdict and every figure, the gripper included (issue 42:
validate placed the grip's part between the simulated jaws, the run had none and faulted
"no part between the jaws").

Both through the real commands, each on a fresh simulated arm powered on at Park; the one
field allowed to differ is a confirm step's ``confirmed`` (assumed by the dry run, given to
the run by --yes).
"""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers the commands on the app)
from projecttree import ROOT
from seqrun.cli.app import app

SHIPPED = sorted(p.stem for p in (ROOT / "sequences").glob("*.yaml"))
#: The fast tier's share: the gripper's sequence (issue 42) and one without a gripper.
FAST = {"grip_part", "totem"}
ASSUMED = {"confirmed"}


def _invoke(*args: str):
    result = CliRunner().invoke(app, [*map(str, args)])
    assert result.exception is None or isinstance(result.exception, SystemExit), result.output
    assert "Traceback" not in result.output
    return result


def _dry_run(file) -> tuple[int, dict]:
    result = _invoke("validate", "--json", file)
    return result.exit_code, json.loads(result.stdout)


def _run(file, folder) -> tuple[int, dict]:
    result = _invoke("run", file, "--virtual-time", "--yes", "--plain", "--no-report",
                     "--log-dir", folder)
    return result.exit_code, json.loads((folder / "report.json").read_text())


def test_every_shipped_sequence_is_here():
    assert "grip_part" in SHIPPED and len(SHIPPED) >= 10


@pytest.mark.parametrize("name", [
    pytest.param(n, marks=() if n in FAST else pytest.mark.slow) for n in SHIPPED])
def test_validate_and_run_agree(name, tmp_path):
    file = ROOT / "sequences" / f"{name}.yaml"
    valid_code, checked = _dry_run(file)
    run_code, report = _run(file, tmp_path / "run")
    dry = checked["dry_run"]
    assert (valid_code, run_code) == (0, 0), (checked.get("errors"), dry and dry["message"],
                                              report["message"])
    assert (dry["status"], dry["message"], dry["fault"]) == (
        report["status"], report["message"], report["fault"])
    assert dry["simulated_s"] == report["duration_s"]
    assert dry["planned_motion_s"] == report["planned_duration_s"]
    assert dry["min_heights_mm"] == report["min_heights_mm"]
    assert len(dry["steps"]) == len(report["steps"])
    for ours, theirs in zip(dry["steps"], report["steps"]):
        assert ({k: v for k, v in ours.items() if k not in ASSUMED}
                == {k: v for k, v in theirs.items() if k not in ASSUMED}), ours["number"]


def test_the_grip_holds_the_same_part_in_both(tmp_path):
    file = ROOT / "sequences" / "grip_part.yaml"
    _, checked = _dry_run(file)
    _, report = _run(file, tmp_path / "run")
    for steps in (checked["dry_run"]["steps"], report["steps"]):
        grip = next(s for s in steps if s["kind"] == "grip")
        held = next(s for s in steps if s["kind"] == "check_gripper")
        assert grip["status"] == "passed" and grip["width_mm"] == pytest.approx(40, abs=1)
        assert held["holding"] is True
    record = json.loads((tmp_path / "run" / "record.json").read_text())
    assert "a 40 mm part between the simulated jaws (step 6's grip part_width_mm)" in \
        json.dumps(record)
