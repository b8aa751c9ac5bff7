"""One simulated PRL module: exact motion, state bits and the protocol's refusals."""

from __future__ import annotations

import math
import struct

import pytest

from seqrun.clock import VirtualClock
from seqrun.powercube.codec import (
    BroadcastRequest,
    CommandAck,
    CommandRequest,
    GetParam,
    GetParamAck,
    MotionAck,
    MotionExtAck,
    PosStateDio,
    SetMotion,
    SetParam,
    SetParamAck,
    encode,
)
from seqrun.powercube.protocol import (
    CommandId,
    ConfigFlag,
    MotionMode,
    ParamId,
    ShortState,
    StateFlag,
)
from seqrun.sim.module import ModuleOptions, SimModule, plan_ramp

F = StateFlag
S = ShortState
LIMIT = struct.unpack("<f", struct.pack("<f", 2.0944))[0]  # the module stores float32


def f32(x: float) -> float:
    return struct.unpack("<f", struct.pack("<f", x))[0]


@pytest.fixture
def clock():
    return VirtualClock()


def homed(clock, module_id=1, **kwargs) -> SimModule:
    module = SimModule(module_id, clock, **kwargs)
    module.handle(CommandRequest(module_id, CommandId.HOME))
    return module


def set_param(module, param, value):
    assert module.handle(SetParam(module.module_id, param, value)) == SetParamAck(
        module.module_id, param)


def ramp_to(module, target, vel=None, acc=None, mode=MotionMode.FRAMP):
    if vel is not None:
        set_param(module, ParamId.TARGET_VEL, vel)
    if acc is not None:
        set_param(module, ParamId.TARGET_ACC, acc)
    return module.handle(SetMotion(module.module_id, mode, target))


# -- power-on, Home, defaults ---------------------------------------------------------------


def test_power_on_refuses_motion_until_home(clock):
    module = SimModule(2, clock)
    assert module.state() == F.BRAKEACTIVE | F.RAMP_END
    ack = module.handle(SetMotion(2, MotionMode.FRAMP_ACK, 0.5))
    # Refused, but acknowledged; the extended ack says NOT_OK.
    assert ack == MotionExtAck(2, MotionMode.FRAMP_ACK, 0.0, S.NOT_OK | S.RAMP_END, 0)
    clock.advance(1.0)
    assert module.position() == 0.0 and not module.state() & F.MOTION
    # Home: HOME_OK, brake released, no travel.
    assert module.handle(CommandRequest(2, CommandId.HOME)) == CommandAck(2, CommandId.HOME)
    assert module.state() == F.HOME_OK | F.RAMP_END
    assert module.position() == 0.0
    assert module.handle(SetMotion(2, MotionMode.FRAMP, 0.5)) == MotionAck(2, MotionMode.FRAMP)
    clock.advance(0.01)
    assert module.state() & F.MOTION


def test_home_ok_at_power_on_option(clock):
    module = SimModule(1, clock, options=ModuleOptions(home_ok_at_power_on=True))
    assert module.state() == F.HOME_OK | F.RAMP_END


def test_refused_motion_without_ack_when_configured(clock):
    module = SimModule(1, clock, options=ModuleOptions(ack_refused_motion=False))
    assert module.handle(SetMotion(1, MotionMode.FRAMP, 0.5)) is None


def test_defaults_of_a_prl_module(clock):
    module = SimModule(4, clock)
    assert module.parameter(ParamId.DEF_CUBE_VERSION) == 0x4638
    assert module.parameter(ParamId.DEF_ADDRESS) == 4
    assert module.parameter(ParamId.MIN_POS) == -LIMIT
    assert module.parameter(ParamId.MAX_POS) == LIMIT
    assert module.parameter(ParamId.MAX_VEL) == 2.0
    assert module.parameter(ParamId.MAX_ACC) == 2.0
    assert module.parameter(ParamId.SETUP) & 0x4  # ABSOLUTE -> the ROS driver's "PRL"
    assert module.parameter(ParamId.DEF_CONFIG) & ConfigFlag.LINEAR == 0
    assert module.parameter(ParamId.ACT_POS) == 0.0


def test_every_parameter_answers_with_its_wire_type(clock):
    module = homed(clock, 3)
    for param in ParamId:
        ack = module.handle(GetParam(3, param))
        assert isinstance(ack, GetParamAck) and ack.param == param
        can_id, data = encode(ack)  # raises if the value does not fit the wire type
        assert can_id == 0x0A3 and data[:2] == bytes([0x0A, param])


def test_reference_vectors_for_reads(clock):
    # Vector 4: ActPos of a module at 0.5 rad -> 0A 3C 00 00 00 3F
    module = homed(clock, 3, position=0.5)
    assert encode(module.handle(GetParam(3, ParamId.ACT_POS))) == (
        0x0A3, bytes.fromhex("0A3C0000003F"))
    # Vector 5: CubeState of an idle homed module -> HOME_OK|RAMP_END = 0x8002
    assert encode(module.handle(GetParam(3, ParamId.CUBE_STATE))) == (
        0x0A3, bytes.fromhex("0A2702800000"))
    # Vector 17: DefCubeVersion 0x4638
    assert encode(module.handle(GetParam(3, ParamId.DEF_CUBE_VERSION)))[1] == bytes.fromhex(
        "0A1D3846")


def test_read_only_parameters_are_acked_and_ignored(clock):
    module = homed(clock)
    set_param(module, ParamId.ACT_POS, 1.0)
    set_param(module, ParamId.TARGET_POS, 1.0)  # the thesis thought TargetPos writable
    set_param(module, ParamId.DEF_CUBE_VERSION, 0x1234)
    assert module.parameter(ParamId.ACT_POS) == 0.0
    assert module.parameter(ParamId.TARGET_POS) == 0.0
    assert module.parameter(ParamId.DEF_CUBE_VERSION) == 0x4638
    clock.advance(1.0)
    assert module.position() == 0.0  # TargetPos + nothing does not move


def test_writable_parameters_and_tick_twins(clock):
    module = homed(clock)
    set_param(module, ParamId.MAX_VEL, 0.77)
    assert module.parameter(ParamId.MAX_VEL) == f32(0.77)
    ratio = module.parameter(ParamId.INC_RATIO)
    set_param(module, ParamId.IMIN_POS, -10000)
    assert module.parameter(ParamId.MIN_POS) == pytest.approx(-10000 * ratio, rel=1e-6)
    assert module.parameter(ParamId.IMIN_POS) == -10000


# -- ramps ------------------------------------------------------------------------------


def test_trapezoid_duration_and_exact_stop(clock):
    module = homed(clock)
    ramp_to(module, 1.0, vel=0.5, acc=1.0)
    # 0.5 s accelerating (0.125 rad), 1.5 s at 0.5 rad/s (0.75 rad), 0.5 s braking.
    expected = [(0.25, 0.03125, 0.25, F.RAMP_ACC), (0.5, 0.125, 0.5, F.RAMP_STEADY),
                (1.0, 0.375, 0.5, F.RAMP_STEADY), (2.25, 0.96875, 0.25, F.RAMP_DEC)]
    for t, pos, vel, phase in expected:
        clock.sleep_until(t)
        assert module.position() == pytest.approx(pos, abs=1e-12)
        assert module.velocity() == pytest.approx(vel, abs=1e-12)
        assert module.state() == F.HOME_OK | F.MOTION | phase
    clock.sleep_until(2.5 - 1e-9)
    assert module.state() & F.MOTION
    clock.sleep_until(2.5)
    assert module.position() == 1.0  # exactly the target
    assert module.velocity() == 0.0
    assert module.state() == F.HOME_OK | F.RAMP_END


def test_triangle_when_the_distance_is_short(clock):
    module = homed(clock)
    ramp_to(module, -0.25, vel=1.0, acc=1.0)
    clock.sleep_until(0.5)  # peak: sqrt(a*d) = 0.5 rad/s, reached at 0.5 s
    assert module.velocity() == pytest.approx(-0.5)
    assert module.state() & F.RAMP_DEC
    clock.sleep_until(1.0)
    assert module.position() == -0.25 and module.state() & F.RAMP_END


def test_limits_are_min_of_target_and_max(clock):
    module = homed(clock)
    set_param(module, ParamId.MAX_ACC, 0.5)
    ramp_to(module, 2.0, vel=3.0, acc=4.0)  # -> vmax = MaxVel 2.0, amax = MaxAcc 0.5
    # Triangle: peak sqrt(0.5 * 2) = 1.0 rad/s at 2 s, done at 4 s.
    clock.sleep_until(2.0)
    assert module.velocity() == pytest.approx(1.0)
    clock.sleep_until(4.0)
    assert module.position() == 2.0 and not module.state() & F.MOTION
    set_param(module, ParamId.MAX_VEL, 0.25)
    ramp_to(module, 1.0, vel=1.0, acc=1.0)  # 1 rad at 0.25 rad/s, acc 0.5: 4.5 s
    clock.sleep_until(4.0 + 4.5 - 1e-6)
    assert module.state() & F.MOTION
    clock.sleep_until(8.5)
    assert module.position() == 1.0


def test_replan_from_current_position_and_velocity(clock):
    module = homed(clock)
    ramp_to(module, 1.0, vel=0.5, acc=1.0)
    clock.sleep_until(1.0)  # at 0.375 rad moving +0.5 rad/s
    ramp_to(module, 0.0)
    # Brakes 0.5 s (to 0.5 rad), then 0.5 rad back: 0.5 + 0.5 + 0.5 s.
    clock.sleep_until(1.25)
    assert module.velocity() == pytest.approx(0.25)  # velocity is continuous
    assert module.state() & F.RAMP_DEC
    clock.sleep_until(1.5)
    assert module.position() == pytest.approx(0.5) and module.velocity() == pytest.approx(0)
    clock.sleep_until(3.0 - 1e-6)
    assert module.state() & F.MOTION
    clock.sleep_until(3.0)
    assert module.position() == 0.0 and module.state() & F.RAMP_END


def test_replan_slows_down_when_faster_than_new_limit(clock):
    assert plan_ramp(0.0, 1.0, 10.0, 0.5, 1.0) == [(0.5, -1.0), (19.0, 0.0),
                                                    (0.5, -1.0)]


def test_target_clamped_into_soft_limits(clock):
    module = homed(clock)
    ramp_to(module, 3.0, vel=2.0, acc=2.0)
    assert module.parameter(ParamId.TARGET_POS) == LIMIT
    clock.advance(5.0)
    assert module.position() == LIMIT
    assert module.state() == F.HOME_OK | F.RAMP_END  # no fault: it stopped at the limit


def test_result_does_not_depend_on_how_often_the_module_is_touched():
    clock_a, clock_b = VirtualClock(), VirtualClock()
    a, b = homed(clock_a), homed(clock_b)
    for module in (a, b):
        ramp_to(module, 1.3, vel=0.7, acc=0.9)
    for k in range(1, 1701):
        clock_a.sleep_until(k / 1000)
        a.position()
    clock_b.advance(1.7)
    assert a.position() == b.position() and a.velocity() == b.velocity()


# -- velocity mode and soft limits ---------------------------------------------------------


def test_velocity_mode_runs_to_the_soft_limit_and_stops_there(clock):
    module = homed(clock)
    set_param(module, ParamId.TARGET_ACC, 1.0)
    module.handle(SetMotion(1, MotionMode.FVEL, 0.5))
    clock.sleep_until(0.25)
    assert module.velocity() == pytest.approx(0.25) and module.state() & F.RAMP_ACC
    clock.sleep_until(1.0)
    assert module.state() & F.RAMP_STEADY
    reach = 0.5 + (LIMIT - 0.125) / 0.5  # 4.4388 s
    clock.sleep_until(reach - 1e-6)
    assert module.state() & F.MOTION and not module.state().is_fault
    clock.sleep_until(reach + 1.0)
    assert module.position() == LIMIT
    assert module.velocity() == 0.0
    assert module.state() == F.HOME_OK | F.BEYOND_SOFT | F.ERROR | F.HALTED | F.RAMP_END
    # Refused until Reset; then only back into the range.
    assert module.handle(SetMotion(1, MotionMode.FVEL_ACK, -0.1)).state & S.NOT_OK
    module.handle(CommandRequest(1, CommandId.RESET))
    assert module.state() == F.HOME_OK | F.RAMP_END
    assert module.handle(SetMotion(1, MotionMode.FVEL_ACK, 0.1)).state & S.NOT_OK
    ack = module.handle(SetMotion(1, MotionMode.FVEL_ACK, -0.1))
    assert ack.state == S.RAMP_END and ack.position == LIMIT


def test_soft_limit_flags_are_configurable(clock):
    module = homed(clock, options=ModuleOptions(soft_limit_flags=F(0),
                                                velocity_mode_acceleration=False))
    module.handle(SetMotion(1, MotionMode.FVEL, -1.0))
    clock.sleep_until(LIMIT + 0.001)  # 1 rad/s from 0 to -LIMIT
    assert module.position() == -LIMIT
    assert module.state() == F.HOME_OK | F.BEYOND_SOFT | F.RAMP_END


def test_module_outside_its_limits_moves_back_only(clock):
    # Park: module 4 at 0, then the user limits are written: MinPos = 0.32 deg.
    module = homed(clock, 4)
    min_pos = math.radians(0.32)
    set_param(module, ParamId.MIN_POS, min_pos)
    set_param(module, ParamId.MAX_POS, math.radians(240.32))
    assert module.state() == F.HOME_OK | F.RAMP_END  # being outside is no fault
    ack = module.handle(SetMotion(4, MotionMode.FVEL_ACK, -0.1))
    assert ack.state == S.NOT_OK | S.RAMP_END  # further out: refused
    ack = module.handle(SetMotion(4, MotionMode.FRAMP_ACK, -1.0))  # clamped to MinPos
    assert ack.state == S.RAMP_END
    clock.advance(2.0)
    assert module.position() == f32(min_pos)
    assert module.state() == F.HOME_OK | F.RAMP_END


def test_velocity_back_into_range_crosses_min_pos_without_fault(clock):
    module = homed(clock, 4)
    set_param(module, ParamId.MIN_POS, 0.01)
    set_param(module, ParamId.TARGET_ACC, 1.0)
    module.handle(SetMotion(4, MotionMode.FVEL, 0.1))
    clock.advance(1.0)
    assert module.position() == pytest.approx(0.005 + 0.9 * 0.1)
    assert not module.state().is_fault


# -- halt, reset ---------------------------------------------------------------------------


def test_halt_stops_at_once_and_refuses_until_reset(clock):
    module = homed(clock)
    ramp_to(module, 1.0, vel=0.5, acc=1.0)
    clock.sleep_until(1.0)
    assert module.handle(CommandRequest(1, CommandId.HALT)) == CommandAck(1, CommandId.HALT)
    assert module.velocity() == 0.0
    clock.advance(1.0)
    assert module.position() == 0.375
    assert module.state() == F.HOME_OK | F.HALTED | F.RAMP_END
    ack = ramp_to(module, 0.0, mode=MotionMode.FRAMP_ACK)
    assert ack.state == S.NOT_OK | S.RAMP_END and ack.position == 0.375
    clock.advance(1.0)
    assert module.position() == 0.375
    module.handle(CommandRequest(1, CommandId.RESET))
    assert module.state() == F.HOME_OK | F.RAMP_END
    ramp_to(module, 0.0)
    clock.advance(5.0)
    assert module.position() == 0.0


def test_reset_clears_every_resettable_fault(clock):
    module = homed(clock)
    module.inject("tow_error")
    assert module.state() == F.HOME_OK | F.ERROR | F.TOW_ERROR | F.HALTED | F.RAMP_END
    module.handle(BroadcastRequest(CommandId.RESET))
    assert module.state() == F.HOME_OK | F.RAMP_END


def test_home_is_refused_while_halted(clock):
    module = SimModule(1, clock)
    module.handle(CommandRequest(1, CommandId.HALT))
    assert module.handle(CommandRequest(1, CommandId.HOME)) == CommandAck(1, CommandId.HOME)
    assert not module.state() & F.HOME_OK


# -- steps -----------------------------------------------------------------------------------


def test_step_interpolates_linearly_and_buffers_the_next(clock):
    module = homed(clock)
    module.handle(SetMotion(1, MotionMode.FSTEP, 0.1, 100))
    clock.sleep_until(0.05)
    assert module.position() == pytest.approx(0.05)
    assert module.state() == F.HOME_OK | F.MOTION | F.INPROGRESS
    # A second step while the first runs waits for it.
    ack = module.handle(SetMotion(1, MotionMode.FSTEP_ACK, 0.3, 100))
    assert ack.position == f32(module.position()) and ack.state == S.MOTION | S.INPROGRESS
    assert module.state() == F.HOME_OK | F.MOTION | F.INPROGRESS | F.FULLBUFFER
    clock.sleep_until(0.1)
    assert module.position() == pytest.approx(0.1)
    assert module.state() == F.HOME_OK | F.MOTION | F.INPROGRESS
    clock.sleep_until(0.15)
    assert module.position() == pytest.approx(0.2)
    clock.sleep_until(0.2)
    assert module.position() == pytest.approx(0.3)
    assert module.state() == F.HOME_OK | F.RAMP_END


def test_step_without_buffering_replaces_the_running_step(clock):
    module = homed(clock, options=ModuleOptions(step_buffering=False))
    module.handle(SetMotion(1, MotionMode.FSTEP, 0.1, 100))
    clock.sleep_until(0.05)
    module.handle(SetMotion(1, MotionMode.FSTEP, 0.0, 50))
    clock.sleep_until(0.075)
    assert module.position() == pytest.approx(0.025)
    clock.sleep_until(0.1)
    assert module.position() == 0.0


def test_step_is_not_faster_than_max_vel(clock):
    module = homed(clock)
    module.handle(SetMotion(1, MotionMode.FSTEP, 1.0, 100))  # 10 rad/s wanted, MaxVel 2
    clock.sleep_until(0.5 - 1e-6)
    assert module.state() & F.INPROGRESS
    clock.sleep_until(0.5)
    assert module.position() == 1.0


def test_reference_vector_6_step_ack(clock):
    module = homed(clock, 4, position=-0.2)
    set_param(module, ParamId.TARGET_VEL, 0.1)
    ramp_to(module, -1.0)
    clock.advance(0.001)  # moving now; FSTEP_ACK -0.25 rad in 60 ms
    request_pos = module.position()
    ack = module.handle(SetMotion(4, MotionMode.FSTEP_ACK, -0.25, 60))
    assert ack == MotionExtAck(4, MotionMode.FSTEP_ACK, f32(request_pos),
                               S.MOTION, 0)


# -- sync motion, watchdog, acks --------------------------------------------------------------


def test_sync_motion_waits_for_start_move_broadcast(clock):
    module = homed(clock)
    set_param(module, ParamId.CONFIG, int(ConfigFlag.SYNC_MOTION))
    ramp_to(module, 0.25, vel=1.0, acc=1.0)
    clock.advance(1.0)
    assert module.position() == 0.0 and not module.state() & F.MOTION
    module.handle(BroadcastRequest(CommandId.START_MOVE, 0))
    clock.advance(0.5)
    assert module.position() == pytest.approx(0.125)
    clock.advance(0.5)
    assert module.position() == 0.25


def test_start_move_without_sync_bit_does_nothing(clock):
    module = homed(clock)
    module.handle(BroadcastRequest(CommandId.START_MOVE))
    assert module.state() == F.HOME_OK | F.RAMP_END


def test_watchdog_armed_by_first_refresh_then_expires(clock):
    module = homed(clock)
    set_param(module, ParamId.CONFIG, int(ConfigFlag.WATCHDOG_ENABLE))
    clock.advance(1.0)  # enabled but never refreshed: not armed
    assert not module.state().is_fault
    module.handle(BroadcastRequest(CommandId.WATCHDOG_REFRESH, 0))  # armed at 1.0
    ramp_to(module, 1.0, vel=0.5, acc=1.0)
    clock.sleep_until(1.04)
    module.handle(BroadcastRequest(CommandId.WATCHDOG_REFRESH))  # deadline 1.09
    clock.sleep_until(1.0899)
    assert module.state() & F.MOTION and not module.state().is_fault
    clock.sleep_until(1.2)
    assert module.state() == F.HOME_OK | F.HALTED | F.ERROR | F.COMM_ERROR | F.RAMP_END
    # Stopped where it was at 1.09 s (0.09 s into the ramp).
    assert module.position() == pytest.approx(0.5 * 0.09 ** 2)
    module.handle(CommandRequest(1, CommandId.RESET))
    clock.advance(1.0)  # Reset disarmed it: no new expiry
    assert module.state() == F.HOME_OK | F.RAMP_END


def test_addressed_watchdog_refresh_arms_and_is_acked(clock):
    module = homed(clock, options=ModuleOptions(watchdog_timeout=0.2))
    set_param(module, ParamId.CONFIG, int(ConfigFlag.WATCHDOG_ENABLE))
    assert module.handle(CommandRequest(1, CommandId.WATCHDOG_REFRESH)) == CommandAck(
        1, CommandId.WATCHDOG_REFRESH)
    clock.advance(0.19)
    assert not module.state().is_fault
    clock.advance(0.02)
    assert module.state() & F.COMM_ERROR


def test_disable_ack_config_bit(clock):
    module = homed(clock)
    assert module.handle(SetParam(1, ParamId.CONFIG, int(ConfigFlag.DISABLE_ACK))) is None
    assert module.handle(GetParam(1, ParamId.ACT_POS)) is None


def test_fpos_state_dio(clock):
    module = homed(clock, 6, position=1.2)
    assert module.parameter(ParamId.FPOS_STATE_DIO) == PosStateDio(f32(1.2), S.RAMP_END, 0)
    unhomed = SimModule(6, clock, position=1.2)
    # Vector 11: not homed -> NOT_OK; ack bytes 0A 62 9A 99 99 3F (01|20) 00
    ack = unhomed.handle(GetParam(6, ParamId.FPOS_STATE_DIO))
    assert encode(ack) == (0x0A6, bytes.fromhex("0A629A99993F2100"))


# -- injected module faults ------------------------------------------------------------------


def test_stuck_joint_keeps_acking_without_error(clock):
    module = homed(clock)
    ramp_to(module, 1.0, vel=0.5, acc=1.0)
    clock.sleep_until(1.0)
    module.inject("stuck")
    clock.sleep_until(3.0)
    assert module.position() == 0.375
    assert module.parameter(ParamId.DELTA_POS) == pytest.approx(1.0 - 0.375)
    assert not module.state().is_fault
    assert module.handle(GetParam(1, ParamId.ACT_POS)).value == 0.375


def test_missing_module_never_answers_and_freezes(clock):
    module = homed(clock)
    ramp_to(module, 1.0, vel=0.5, acc=1.0)
    clock.sleep_until(1.0)
    module.inject("missing")
    assert module.handle(GetParam(1, ParamId.ACT_POS)) is None
    module.handle(BroadcastRequest(CommandId.HALT))
    clock.advance(2.0)
    assert module.position() == 0.375 and not module.state() & F.HALTED


def test_integer_modes_use_ticks(clock):
    module = homed(clock)
    ratio = module.parameter(ParamId.INC_RATIO)  # rad per tick
    ticks = 20000
    ack = module.handle(SetMotion(1, MotionMode.IRAMP_ACK, ticks))
    assert ack.position == 0 and ack.state == S.RAMP_END
    clock.advance(5.0)
    assert module.position() == pytest.approx(ticks * ratio)
    assert module.parameter(ParamId.IPOS) == ticks
    module.handle(SetMotion(1, MotionMode.IVEL, -ticks))  # ticks/s
    clock.advance(0.5)
    assert module.velocity() == pytest.approx(-ticks * ratio)


def test_current_mode_is_not_simulated_and_refused(clock):
    module = homed(clock)
    ack = module.handle(SetMotion(1, MotionMode.FCUR_ACK, 1.0))
    assert ack.state & S.NOT_OK
    ack = module.handle(SetMotion(1, MotionMode.ICUR, 100))
    assert ack == MotionAck(1, MotionMode.ICUR)
    clock.advance(1.0)
    assert module.position() == 0.0


def test_a_read_at_rest_repeats_its_acknowledge_and_a_changed_reading_makes_a_new_one():
    # The module hands out the same immutable acknowledge while its reading is unchanged
    # (the wire then encodes it once); any change, even 0.0 -> -0.0, makes a new one.
    clock = VirtualClock()
    module = SimModule(3, clock)
    read = GetParam(3, ParamId.FPOS_STATE_DIO)
    first = module.handle(read, 0.0)
    assert module.handle(read, 0.1) is first
    module.set_position(-0.0, 0.2)
    negative_zero = module.handle(read, 0.3)
    assert negative_zero is not first and encode(negative_zero) != encode(first)
    assert encode(negative_zero)[1][2:6] == struct.pack("<f", -0.0)
    module.set_position(0.5, 0.4)
    moved = module.handle(read, 0.5)
    assert moved.value.position == pytest.approx(0.5) and moved is not negative_zero
