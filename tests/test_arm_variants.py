"""Arm variants are files: a joint declared absent (no module on the bus; the kinematics
keep its locked angle) and an arm on module ids other than 1..7."""

from __future__ import annotations

import shutil

import pytest
from typer.testing import CliRunner

from projecttree import ROOT
from seqrun.arm.description import ArmDescription, load_arm
from seqrun.cli import app
from seqrun.clock import VirtualClock
from seqrun.errors import SequenceInvalid
from seqrun.powercube.protocol import StateFlag
from seqrun.service.connection import open_connection
from seqrun.service.runner import run_sequence
from seqrun.sequence.loader import load_sequence

F = StateFlag


def _without_module_3(text: str) -> str:
    old = "  - {name: j3, module: 3, limits_deg: [-180, 180], offset_deg: 0.0, locked: 0.0,"
    assert old in text
    return text.replace(old, "  - {name: j3, module: 3, limits_deg: [-180, 180], "
                             "offset_deg: 0.0, locked: 0.0, present: false,")


def _on_ids_11_to_17(text: str) -> str:
    for m in range(1, 8):
        text = text.replace(f"  - {{name: j{m}, module: {m},", f"  - {{name: j{m}, module: "
                                                                f"{10 + m},")
    assert "module: 17" in text
    return text


@pytest.fixture(params=["absent_j3", "ids_11_17"])
def variant(request, tmp_path):
    root = tmp_path / "campaign"
    for folder in ("sequences", "arms", "poses"):
        shutil.copytree(ROOT / folder, root / folder)
    path = root / "arms" / "lwa3.yaml"
    edit = _without_module_3 if request.param == "absent_j3" else _on_ids_11_to_17
    path.write_text(edit(path.read_text()))
    return request.param, root


def test_the_variant_validates(variant):
    _, root = variant
    result = CliRunner().invoke(app, ["validate", str(root / "sequences" / "totem.yaml")])
    assert result.exit_code == 0, result.output


def test_the_variant_runs_on_a_simulator_with_only_its_modules(variant, tmp_path):
    kind, root = variant
    loaded = load_sequence(root / "sequences" / "totem.yaml")
    arm = load_arm(loaded.arm_path)
    expected = [1, 2, 4, 5, 6, 7] if kind == "absent_j3" else list(range(11, 18))
    assert arm.present_module_ids == expected
    connection = open_connection(force_sim=True, clock=VirtualClock(),
                                 sim_modules=arm.present_module_ids)
    try:
        sim = connection.bus.arm
        assert sim.module_ids == expected        # no module 3 / modules 11..17 only
        outcome = run_sequence(loaded, arm, connection, log_dir=tmp_path / "run",
                               html_report=False, confirm=lambda prompt: True)
        assert outcome.result.exit_code == 0, outcome.result.message
        states = sim.states()
        assert all(s & F.HOME_OK and not s & F.FAULTS for s in states.values())
        assert outcome.result.steps[-1].status == "passed"
    finally:
        connection.close()


def test_nothing_is_sent_to_an_absent_module(tmp_path):
    root = tmp_path / "campaign"
    for folder in ("sequences", "arms", "poses"):
        shutil.copytree(ROOT / folder, root / folder)
    path = root / "arms" / "lwa3.yaml"
    path.write_text(_without_module_3(path.read_text()))
    loaded = load_sequence(root / "sequences" / "totem.yaml")
    arm = load_arm(loaded.arm_path)
    # A simulator that does have module 3: it must hear nothing addressed to it.
    connection = open_connection(force_sim=True, clock=VirtualClock())
    addressed = []
    connection.bus.arm.module(3).handle = lambda request, t=None: addressed.append(request)
    try:
        outcome = run_sequence(loaded, arm, connection, log_dir=tmp_path / "run",
                               html_report=False, confirm=lambda prompt: True)
        assert outcome.result.exit_code == 0, outcome.result.message
    finally:
        connection.close()
    assert [r for r in addressed if getattr(r, "module", None) == 3] == []


def test_an_absent_joint_must_be_locked(tmp_path):
    path = tmp_path / "arm.yaml"
    text = (ROOT / "arms" / "lwa3.yaml").read_text()
    text = text.replace("  - {name: j2, module: 2, limits_deg: [-120, 120], offset_deg: 90.0,",
                        "  - {name: j2, module: 2, limits_deg: [-120, 120], offset_deg: 90.0, "
                        "present: false,")
    path.write_text(text)
    with pytest.raises(SequenceInvalid) as err:
        load_arm(path)
    assert "j2 is not present (present: false): give its fixed angle as locked" in str(err.value)


def test_the_shipped_arm_has_every_module_present():
    arm = load_arm(ROOT / "arms" / "lwa3.yaml")
    assert arm.present_module_ids == arm.module_ids == list(range(1, 8))
    assert "present" in ArmDescription.model_json_schema()["$defs"]["Joint"]["properties"]
