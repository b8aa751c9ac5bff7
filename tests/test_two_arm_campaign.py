"""Two arms, one campaign (issue 28, item 1): ``seqrun.toml`` names each arm (id, arm file,
bus, base pose in the facility frame) and every arm resolves to an arm context of its own;
today's one-arm format keeps resolving as before."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from seqrun.errors import UserInputError
from seqrun.sequence.project import ConfigInvalid, open_project
from seqrun.service.arm_context import resolve_context, resolve_contexts
from twoarmskit import halted, quiet, two_served_campaign

TWO_ARMS = """\
[campaign]
name = "Dual capture"

[arms.A]
arm = "lwa3"
base = { position_mm = [0, 0, 0], rpy_deg = [0, 0, 0] }

[arms.B]
arm = "lwa3"
bus = { interface = "virtual", channel = "armB" }
base = { position_mm = [1200, 0, 0], rpy_deg = [0, 0, 180] }
"""


@pytest.fixture
def quiet_env(tmp_path, monkeypatch):
    return quiet(tmp_path, monkeypatch)


def campaign(folder, text: str):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "seqrun.toml").write_text(text)
    return open_project(folder)


def test_two_arms_resolve_to_two_contexts(quiet_env):
    project = campaign(quiet_env / "dual", TWO_ARMS)
    a, b = resolve_contexts(project=project)
    assert (a.arm_id, b.arm_id) == ("A", "B")
    assert a.arm.name == b.arm.name
    assert a.bus.is_simulator and not b.bus.is_simulator
    assert b.bus.config["channel"] == "armB" and "seqrun.toml" in b.bus.source
    assert (a.part, b.part) == ("A", "B")
    np.testing.assert_allclose(b.base_transform()[:3, 3], [1200, 0, 0])
    np.testing.assert_allclose(b.base_transform()[:3, 0], [-1, 0, 0], atol=1e-12)
    assert b.arm_text().startswith("arm B: ")
    # one of them by id, the same as the list gives
    assert resolve_context(project=project, arm_id="B").bus.config == b.bus.config
    assert [c.arm_id for c in resolve_contexts(project=project, arm_ids=["B"])] == ["B"]


def test_an_unknown_or_missing_arm_id_is_one_line(quiet_env):
    project = campaign(quiet_env / "dual", TWO_ARMS)
    with pytest.raises(UserInputError, match="unknown arm 'C'.*arms A, B"):
        resolve_contexts(project=project, arm_ids=["C"])
    with pytest.raises(UserInputError, match="has arms A, B: name one"):
        resolve_context(project=project)
    with pytest.raises(UserInputError, match="each arm of this campaign has its own"):
        resolve_contexts(project=project, interface="virtual", channel="x")


def test_the_one_arm_format_resolves_as_before(quiet_env):
    project = campaign(quiet_env / "one", '[campaign]\narm = "lwa3"\n'
                                          '[bus]\ninterface = "virtual"\nchannel = "c0"\n')
    (only,) = resolve_contexts(project=project)
    assert only.arm_id is None and only.part == ""
    assert only.bus.config["channel"] == "c0"
    np.testing.assert_allclose(only.base_transform(), np.eye(4))
    assert only.arm_text().startswith("arm '")
    with pytest.raises(UserInputError, match="names no arms"):
        resolve_contexts(project=project, arm_ids=["A"])


@pytest.mark.parametrize("text, where, message", [
    ('[arms.A]\narm = "lwa3"\n[arms.A.base]\nposition_mm = [0, 0]\n', "4:1",
     "arms.A.base.position_mm"),
    ('[arms.A]\nbase = { position_mm = [0, 0, true] }\n', "2:1", "three finite numbers"),
    ('[arms.1A]\narm = "lwa3"\n', "1:1", "arm id '1A'"),
    ('[arms.A]\narm = "lwa3"\nbsu = 1\n', "3:1", "arms.A.bsu: unknown key"),
    ('[campaign]\narm = "lwa3"\n[arms.A]\narm = "lwa3"\n', "1:1",
     "[campaign] arm and [arms.*] both name arms"),
    ('[bus]\ninterface = "virtual"\n[arms.A]\n', "1:1", "[bus] and [arms.*] both name buses"),
    ('[arms.A]\nbus = { interface = "virtual", channel = "x" }\n'
     '[arms.B]\nbus = { interface = "virtual", channel = "x" }\n', "1:1", "the same bus"),
])
def test_a_bad_arms_table_is_file_line_col(quiet_env, text, where, message):
    with pytest.raises(ConfigInvalid) as caught:
        campaign(quiet_env / "bad", text)
    line = str(caught.value).splitlines()[0]
    assert f"seqrun.toml:{where}:" in line and message in line, line


# ------------------------------------------------------------------ status / halt / reset
@pytest.fixture
def two_served(tmp_path, monkeypatch):
    """Two simulated arms, each its own server (own serials and power-on pose), named by
    a campaign with arms A and B."""
    with two_served_campaign(tmp_path, monkeypatch) as arms:
        yield arms


def test_halt_halts_every_arm_and_confirms_each(two_served):
    from typer.testing import CliRunner

    from seqrun.cli import app

    result = CliRunner().invoke(app, ["halt"])
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert [l.startswith("arm A: ") for l in lines].count(True) == 1
    assert [l.startswith("arm B: ") for l in lines].count(True) == 1
    assert sum("Halt confirmed by modules 1, 2, 3, 4, 5, 6, 7" in l for l in lines) == 2
    assert halted(two_served["A"]) and halted(two_served["B"])


def test_halt_and_reset_one_arm_by_its_id(two_served):
    from typer.testing import CliRunner

    from seqrun.cli import app

    result = CliRunner().invoke(app, ["halt", "--arm-id", "B"])
    assert result.exit_code == 0, result.output
    assert halted(two_served["B"]) and not halted(two_served["A"])
    assert "arm A" not in result.output
    result = CliRunner().invoke(app, ["reset", "--arm-id", "B"])
    assert result.exit_code == 0, result.output
    assert not halted(two_served["B"])
    result = CliRunner().invoke(app, ["halt", "--arm-id", "C"])
    assert result.exit_code == 2
    assert result.output.strip() == "error: unknown arm 'C': campaign " \
        f"{Path.cwd()} has arms A, B"


def test_status_of_every_arm_reads_each_its_own_arm(two_served):
    import json

    from typer.testing import CliRunner

    from seqrun.cli import app

    from seqrun.powercube.protocol import StateFlag

    two_served["B"].network.arm.module(3)._flags |= StateFlag.HALTED  # only B's j3
    result = CliRunner().invoke(app, ["status", "--json"])
    assert result.exit_code == 0, result.output
    a, b = [json.loads(line) for line in result.output.splitlines() if line.startswith("{")]
    assert (a["arm"], b["arm"]) == ("A", "B")  # each line says whose arm it is
    assert "HALTED" not in (a["joints"][2]["state"] or "")
    assert "HALTED" in b["joints"][2]["state"]
    result = CliRunner().invoke(app, ["status", "--watch"])
    assert result.exit_code == 2 and "--watch follows one arm" in result.output
    result = CliRunner().invoke(app, ["status", "--watch", "--json", "--count", "2",
                                      "--period", "0", "--arm-id", "B"])
    assert result.exit_code == 0, result.output
    assert [json.loads(line)["arm"] for line in result.output.splitlines()] == ["B", "B"]
