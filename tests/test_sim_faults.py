"""Fault specs and the faults' effect on the simulated arm (virtual time)."""

from __future__ import annotations

import pytest

from seqrun.clock import VirtualClock
from seqrun.powercube.codec import (
    BroadcastRequest,
    CommandRequest,
    GetParam,
    SetMotion,
    SetParam,
    decode_ack,
    encode,
)
from seqrun.powercube.protocol import CommandId, MotionMode, ParamId, StateFlag
from seqrun.sim.arm import SimArm
from seqrun.sim.faults import Fault, parse_fault_spec, parse_faults

F = StateFlag


# -- spec parsing ---------------------------------------------------------------------------


def test_parse_valid_specs():
    assert parse_fault_spec("4:tow_error@2.5") == Fault(4, "tow_error", 2.5)
    assert parse_fault_spec("all:halt@1") == Fault(None, "halt", 1.0)
    assert parse_fault_spec(" 3:drop_acks=0.3@0 ") == Fault(3, "drop_acks", 0.0, 0.3)
    assert parse_fault_spec("ALL:missing@0").module is None
    assert Fault(3, "drop_acks", 0.0, 0.3).spec == "3:drop_acks=0.3@0"


def test_parse_several_specs_in_one_string():
    assert parse_faults("1:halt@1, 2:stuck@2") == [Fault(1, "halt", 1.0), Fault(2, "stuck", 2.0)]
    assert parse_faults([Fault(5, "no_ack", 0.0), "6:missing@3"]) == [
        Fault(5, "no_ack", 0.0), Fault(6, "missing", 3.0)]
    assert parse_faults(None) == []


@pytest.mark.parametrize("spec, message", [
    ("0:halt@1", "module must be 1..31 or 'all', got 0"),
    ("32:halt@1", "module must be 1..31 or 'all', got 32"),
    ("x:halt@1", "module must be 1..31 or 'all', got 'x'"),
    ("4:explode@1", ("unknown kind 'explode' (one of tow_error, halt, no_ack, drop_acks, "
                     "stuck, missing)")),
    ("4:halt", "missing '@SECONDS'"),
    ("4:halt@-1", "time must be >= 0 seconds, got -1"),
    ("4:halt@soon", "time must be seconds, got 'soon'"),
    ("4:drop_acks=0@1", "rate must be in (0, 1], got 0"),
    ("4:drop_acks=1.5@1", "rate must be in (0, 1], got 1.5"),
    ("4:drop_acks@1", "drop_acks needs a rate"),
    ("4:halt=0.5@1", "kind 'halt' takes no rate"),
    ("halt@1", "expected MODULE:KIND[=RATE]@SECONDS"),
])
def test_bad_specs_have_one_line_messages(spec, message):
    with pytest.raises(ValueError) as info:
        parse_fault_spec(spec)
    text = str(info.value)
    assert message in text and repr(spec) in text and "\n" not in text


def test_fault_object_validates():
    with pytest.raises(ValueError, match="unknown fault kind"):
        Fault(1, "boom", 0.0)
    with pytest.raises(ValueError, match="rate in"):
        Fault(1, "drop_acks", 0.0)


# -- faults on the arm ----------------------------------------------------------------------


def request(arm, req, t=None):
    """Send one request frame; return the decoded acks."""
    can_id, data = encode(req)
    return [decode_ack(r.can_id, r.data) for r in arm.handle_frame(can_id, data, t)]


def started_arm(clock, faults=(), **kwargs) -> SimArm:
    arm = SimArm(clock, faults=faults, **kwargs)
    request(arm, BroadcastRequest(CommandId.HOME))
    return arm


def test_tow_error_at_its_time_stops_the_joint_there():
    clock = VirtualClock()
    arm = started_arm(clock, ["4:tow_error@2.5"])
    request(arm, SetParam(4, ParamId.TARGET_VEL, 0.1))
    request(arm, SetMotion(4, MotionMode.FVEL, 0.1))
    clock.advance(2.0)
    assert arm.states()[4] & F.MOTION
    clock.advance(2.0)  # nobody looked at 2.5 s; the fault still hits at 2.5 s
    module = arm.module(4)
    assert module.state() == F.HOME_OK | F.ERROR | F.TOW_ERROR | F.HALTED | F.RAMP_END
    assert module.position() == pytest.approx(0.0025 + 0.1 * (2.5 - 0.05))
    assert [f.spec for _, f in arm.applied_faults] == ["4:tow_error@2.5"]


def test_halt_all_is_the_emergency_button():
    clock = VirtualClock()
    arm = started_arm(clock, ["all:halt@1"])
    clock.advance(1.0)
    assert all(state & F.HALTED for state in arm.states().values())
    request(arm, BroadcastRequest(CommandId.RESET))
    assert all(state == F.HOME_OK | F.RAMP_END for state in arm.states().values())


def test_no_ack_module_executes_but_never_answers():
    clock = VirtualClock()
    arm = started_arm(clock, ["2:no_ack@0"])
    assert request(arm, GetParam(2, ParamId.ACT_POS)) == []
    assert request(arm, SetMotion(2, MotionMode.FRAMP, 0.1)) == []
    clock.advance(1.0)
    assert arm.positions()[2] == pytest.approx(0.1, abs=1e-7)  # it did move
    request(arm, BroadcastRequest(CommandId.HALT))
    assert arm.states()[2] & F.HALTED  # and still obeys broadcasts
    assert len(request(arm, GetParam(3, ParamId.ACT_POS))) == 1


def test_drop_acks_is_seeded_and_near_its_rate():
    def answered(seed):
        arm = SimArm(VirtualClock(), faults=["3:drop_acks=0.3@0"], seed=seed)
        return [bool(request(arm, GetParam(3, ParamId.ACT_POS))) for _ in range(1000)]

    first = answered(7)
    assert answered(7) == first  # deterministic
    assert answered(8) != first
    assert 650 <= sum(first) <= 750


def test_stuck_module_acks_normally_without_moving():
    clock = VirtualClock()
    arm = started_arm(clock, ["5:stuck@0"])
    acks = request(arm, SetMotion(5, MotionMode.FRAMP_ACK, 0.5))
    assert acks[0].state == 0x20  # RAMP_END, no NOT_OK
    clock.advance(3.0)
    assert arm.positions()[5] == 0.0
    assert not arm.states()[5].is_fault


def test_missing_module_is_silent_and_still():
    clock = VirtualClock()
    arm = started_arm(clock, ["6:missing@0.5"])
    request(arm, SetMotion(6, MotionMode.FVEL, 0.2))
    clock.advance(2.0)
    assert request(arm, GetParam(6, ParamId.ACT_POS)) == []
    assert request(arm, CommandRequest(6, CommandId.RESET)) == []
    frozen = arm.positions()[6]
    clock.advance(1.0)
    assert arm.positions()[6] == frozen > 0.0


def test_inject_rejects_unknown_module_and_applies_past_faults_now():
    clock = VirtualClock()
    arm = started_arm(clock)
    with pytest.raises(ValueError, match="has no module 9"):
        arm.inject("9:halt@0")
    clock.advance(5.0)
    arm.inject(Fault(1, "halt", 1.0))
    assert arm.states()[1] & F.HALTED
