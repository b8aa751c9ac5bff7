"""``seqrun home`` in a campaign with several arms (issue 28, item 3): every arm (or those
named with ``--arm-id``) is homed and confirmed on its own bus, one after the other; an arm
that fails does not keep the others from being homed, and the exit code names it."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from seqrun.cli import app
from seqrun.powercube.protocol import StateFlag
from twoarmskit import two_served_campaign

F = StateFlag


@pytest.fixture
def two_arms(tmp_path, monkeypatch):
    """Two simulated arms on two servers (own serials and power-on pose), a campaign with
    arms A and B on them, each arm's zero recorded (A: Park, B: Totem)."""
    from projecttree import shipped_arm
    from seqrun.drivers.base import ArmIdentity
    from seqrun.service.zero import ZeroStore

    arm = shipped_arm()
    with two_served_campaign(tmp_path, monkeypatch) as arms:
        for server, pose in ((arms["A"], "park"), (arms["B"], "totem")):
            ZeroStore(ArmIdentity.of(server.network.arm.serials)).set_record(
                pose, by="test", joints_deg=arm.power_off_joints_deg(pose))
        yield arms


def home(*args: str):
    """``seqrun home``; the operator says yes to each arm's zero question (issue 43: the
    zero is confirmed before every motion after a power-on)."""
    return CliRunner().invoke(app, ["home", *args], input="y\ny\n")


def lines_of(result) -> list[str]:
    """The output's lines (an answer typed to a question ends its line: the test's input
    is not echoed)."""
    return result.output.replace("[y/N] ", "[y/N]\n").strip().splitlines()


def homed(server, modules=range(1, 8)) -> bool:
    states = server.network.arm.states()
    return all(F(states[m]) & F.HOME_OK and not F(states[m]) & F.MOTION for m in modules)


def none_homed(server) -> bool:
    return not any(F(s) & F.HOME_OK for s in server.network.arm.states().values())


def test_home_homes_every_arm_and_confirms_each(two_arms):
    assert none_homed(two_arms["A"]) and none_homed(two_arms["B"])
    result = home()
    assert result.exit_code == 0, result.output
    lines = lines_of(result)
    for arm in "AB":
        verdicts = [l for l in lines if l.startswith(f"arm {arm}: Home confirmed by modules "
                                                      "1, 2, 3, 4, 5, 6, 7 in ")]
        assert len(verdicts) == 1, result.output
    assert homed(two_arms["A"]) and homed(two_arms["B"])


def test_home_of_one_arm_by_its_id_touches_only_that_arm(two_arms):
    result = home("--arm-id", "B", "--joints", "j2,j3")
    assert result.exit_code == 0, result.output
    assert "arm A" not in result.output
    assert "arm B: Home confirmed by modules 2, 3 in " in result.output
    assert homed(two_arms["B"], [2, 3]) and not homed(two_arms["B"], [1])
    assert none_homed(two_arms["A"])


def test_an_arm_that_fails_does_not_stop_the_others_and_is_named(two_arms):
    two_arms["A"].network.arm.module(3)._flags |= F.HALTED      # A's j3 is halted
    result = home()
    assert result.exit_code == 3, result.output
    lines = lines_of(result)
    assert any(l.startswith("error: arm A: home not sent: module(s) 3 halted or in error")
               for l in lines), result.output
    assert "arm B: Home confirmed by modules 1, 2, 3, 4, 5, 6, 7" in result.output
    assert lines[-1] == "error: not confirmed for arm A (every arm was asked)"
    assert homed(two_arms["B"]) and none_homed(two_arms["A"])


def test_home_is_refused_for_the_arm_whose_bus_a_run_holds(two_arms):
    from seqrun.service.arm_context import resolve_context
    from seqrun.service.bus_claim import claim_bus

    key = resolve_context(arm_id="A").bus.key
    assert key is not None
    with claim_bus(*key, "seqrun run sequences/hold.yaml"):
        result = home()
    assert result.exit_code == 2, result.output
    refusal = [l for l in lines_of(result) if l.startswith("error: arm A: ")]
    assert len(refusal) == 1 and "seqrun run sequences/hold.yaml" in refusal[0], \
        result.output
    assert none_homed(two_arms["A"]) and homed(two_arms["B"])
    assert lines_of(result)[-1] == \
        "error: not confirmed for arm A (every arm was asked)"


def test_a_bus_on_the_command_line_is_refused_for_several_arms(two_arms):
    result = CliRunner().invoke(app, ["home", "-i", "virtual", "-c", "x"])
    assert result.exit_code == 2
    assert "each arm of this campaign has its own" in result.output
    assert none_homed(two_arms["A"]) and none_homed(two_arms["B"])


def test_zero_confirmed_per_arm_answers_each_arms_question(two_arms):
    """Issue 45: --zero-confirmed for several arms. ID=POSE answers that arm's zero
    question (checked as for one arm: A stands at Park, B at Totem); nothing is asked."""
    result = CliRunner().invoke(app, ["home", "--zero-confirmed", "A=park",
                                      "--zero-confirmed", "B=totem"], input="")
    assert result.exit_code == 0, result.output
    assert "(--zero-confirmed park)" in result.output
    assert "(--zero-confirmed totem)" in result.output
    assert homed(two_arms["A"]) and homed(two_arms["B"])


def test_a_bare_zero_confirmed_is_every_arms_and_refused_for_the_arm_elsewhere(two_arms):
    """A bare POSE is said for every arm: B's zero is Totem, so B is refused in one line
    naming it, and A (at Park) is homed all the same."""
    result = CliRunner().invoke(app, ["home", "--zero-confirmed", "park"], input="")
    assert result.exit_code == 2, result.output
    lines = lines_of(result)
    assert any(l.startswith("error: arm B: --zero-confirmed park: the zero reference in "
                            "force is ") for l in lines), result.output
    assert homed(two_arms["A"]) and none_homed(two_arms["B"])
