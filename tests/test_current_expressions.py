"""``current_a[J]`` in expressions (issue 39, item 1): the module's actual current
(PowerCube Cur, 0x4D), read when a check, a wait_until or a condition is evaluated; refused
in a monitor (it is not read in the control loop) and checked for its unit."""

from __future__ import annotations

import json
import shutil

import pytest
from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (registers every command)
from projecttree import ROOT, shipped_arm
from seqrun.cli.app import app
from seqrun.clock import VirtualClock
from seqrun.drivers.registry import open_driver
from seqrun.powercube.codec import SetMotion
from seqrun.powercube.protocol import MotionMode, ParamId
from seqrun.service.connection import open_connection

ARM = shipped_arm()


def campaign(tmp_path, steps: str):
    root = tmp_path / "campaign"
    for folder in ("sequences", "arms", "poses"):
        shutil.copytree(ROOT / folder, root / folder)
    path = root / "sequences" / "current.yaml"
    path.write_text("name: current\nsteps:\n  - include: startup.yaml\n" + steps)
    return path


def test_the_driver_reads_each_modules_own_current_mid_ramp():
    connection = open_connection(force_sim=True, clock=VirtualClock())
    driver = open_driver(ARM, connection)
    try:
        driver.reset(None)
        driver.home(None)
        module = ARM.joints[1].module
        driver.transact([SetMotion(module, MotionMode.FRAMP, 0.5)])
        connection.clock.advance(0.2)
        read = driver.read_currents([module, ARM.joints[0].module])
        sim = connection.bus.arm.module(module).parameter(ParamId.CUR)
        assert read[module] == pytest.approx(sim, rel=0.01) and read[module] > 0.1
        assert read[ARM.joints[0].module] == 0.0      # j1 stands still
    finally:
        driver.close()
        connection.close()


def test_a_check_reads_the_current_and_reports_it(tmp_path):
    path = campaign(tmp_path, "  - check: {that: 'current_a[2] < 1.8 and current_a[4] >= 0', "
                              "label: currents at rest}\n")
    result = CliRunner().invoke(app, ["run", str(path), "--virtual-time", "--yes", "--plain",
                                      "--no-report", "--log-dir", str(tmp_path / "run")])
    assert result.exit_code == 0, result.output
    step = json.loads((tmp_path / "run" / "report.json").read_text())["steps"][-1]
    assert step["values"] == {"current_a[2]": 0.0, "current_a[4]": 0.0}


def test_a_check_that_fails_on_the_current_names_its_value(tmp_path):
    path = campaign(tmp_path, "  - check: {that: 'current_a[2] > 0.5'}\n")
    result = CliRunner().invoke(app, ["run", str(path), "--virtual-time", "--yes", "--plain",
                                      "--no-report", "--log-dir", str(tmp_path / "run")])
    assert result.exit_code == 3, result.output
    assert "check failed: current_a[2] > 0.5" in result.output
    step = json.loads((tmp_path / "run" / "report.json").read_text())["steps"][-1]
    assert (step["status"], step["values"]) == ("failed", {"current_a[2]": 0.0})


@pytest.mark.parametrize("steps, message", [
    ("  - move: {pose: totem, monitors: [{while: 'current_a[2] < 1.8'}]}\n",
     "the currents are not read every cycle; watch it with a wait_until or check step"),
    ("  - check: 'current_a[2] < 10 mm'\n", ""),
    ("  - check: 'current_a[8] < 1'\n", ""),
])
def test_validation_refuses_what_cannot_be_read_at_its_line(tmp_path, steps, message):
    path = campaign(tmp_path, steps)
    result = CliRunner().invoke(app, ["validate", str(path)])
    assert result.exit_code == 1, result.output
    assert f"{path}:4:" in result.output, result.output
    assert message in result.output
