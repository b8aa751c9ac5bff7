"""PowerCubeClient driving the simulated LWA 3 (seqrun.sim) through every operation.

Virtual time throughout: a 2-second move takes milliseconds.
"""

from __future__ import annotations

import itertools

import can
import pytest

from seqrun.clock import VirtualClock
from seqrun.errors import ModuleFaultError, ModuleTimeoutError
from seqrun.powercube.client import ModuleReading, PowerCubeClient
from seqrun.powercube.codec import GetParam, MotionAck, MotionExtAck
from seqrun.powercube.protocol import (
    BaudRate,
    ConfigFlag,
    MotionMode,
    ParamId,
    ShortState,
    StateFlag,
)
from seqrun.sim.bus import SimBus

_channels = itertools.count()


@pytest.fixture
def clock():
    return VirtualClock()


@pytest.fixture
def open_client(clock):
    """``open_client(**simbus_kwargs)`` -> a client on a fresh simulated arm."""
    opened = []

    def open_(**kwargs):
        bus = SimBus(channel=f"test-client-sim-{next(_channels)}", clock=clock, **kwargs)
        client = PowerCubeClient(bus, clock, owns_bus=True)
        opened.append(client)
        return client

    yield open_
    for client in opened:
        client.close()


@pytest.fixture
def client(open_client):
    return open_client()


@pytest.fixture
def homed(client):
    client.home()
    return client


def wait_until_still(client, module, timeout=10.0):
    end = client.clock.now() + timeout
    while client.clock.now() < end:
        if not client.read_state(module) & StateFlag.MOTION:
            return
        client.idle(0.05)
    raise AssertionError(f"module {module} still moving")


def test_scan_finds_the_seven_modules_in_one_round_trip(client, clock):
    assert client.scan() == {m: 0x4638 for m in range(1, 8)}
    assert clock.now() < 2 * client.response_timeout


def test_power_on_state_and_readings(client):
    readings = client.read_arm(range(1, 8))
    assert [r.module for r in readings] == list(range(1, 8))
    assert all(r.position == 0.0 for r in readings)
    assert all(r.state & ShortState.NOT_OK for r in readings)  # not homed yet
    assert client.read_pos_state_dio(3) == readings[2]
    state = client.check_ok(1)  # not homed is not a fault
    assert not state & StateFlag.HOME_OK
    assert client.read_position(1) == 0.0 and client.read_velocity(1) == 0.0


def test_home_one_and_all(client):
    client.home(3)
    assert client.read_state(3) & StateFlag.HOME_OK
    assert not client.read_state(4) & StateFlag.HOME_OK
    client.home()
    assert all(r.state == ShortState.RAMP_END for r in client.read_arm(range(1, 8)))


def test_move_ramp(homed, clock):
    ack = homed.move_ramp(2, 0.5, 0.5, 1.0)
    assert ack == MotionAck(2, MotionMode.FRAMP)
    homed.idle(0.3)
    assert homed.read_state(2) & StateFlag.MOTION
    assert 0.0 < homed.read_velocity(2) <= 0.5 + 1e-6
    wait_until_still(homed, 2)
    assert homed.read_position(2) == pytest.approx(0.5, abs=1e-6)
    assert homed.get_param(2, ParamId.TARGET_VEL) == pytest.approx(0.5)
    assert homed.get_param(2, ParamId.TARGET_ACC) == pytest.approx(1.0)


def test_move_ramp_ext_ack_reports_the_position_at_receipt(homed):
    homed.move_ramp(4, 0.2, 1.0, 2.0)
    wait_until_still(homed, 4)
    ack = homed.move_ramp(4, -0.2, 1.0, ext_ack=True)
    assert isinstance(ack, MotionExtAck) and ack.mode == MotionMode.FRAMP_ACK
    assert ack.position == pytest.approx(0.2, abs=1e-6)
    assert not ack.state & ShortState.NOT_OK


def test_move_step(homed):
    assert homed.move_step(5, 0.05, 200) == MotionAck(5, MotionMode.FSTEP)
    homed.idle(0.25)
    assert homed.read_position(5) == pytest.approx(0.05, abs=1e-6)
    ack = homed.move_step(5, 0.1, 100, ext_ack=True)
    assert ack.mode == MotionMode.FSTEP_ACK
    assert ack.position == pytest.approx(0.05, abs=1e-6)


def test_move_velocity(homed):
    assert homed.move_velocity(6, 0.2) == MotionAck(6, MotionMode.FVEL)
    homed.idle(1.0)
    assert homed.read_velocity(6) == pytest.approx(0.2, abs=1e-6)
    ack = homed.move_velocity(6, 0.0, ext_ack=True)
    assert ack.mode == MotionMode.FVEL_ACK and ack.position > 0.1
    homed.idle(1.0)
    assert homed.read_velocity(6) == 0.0


def test_parameters_of_each_wire_type(client):
    client.set_param(1, ParamId.MAX_VEL, 1.0)
    assert client.get_param(1, ParamId.MAX_VEL) == 1.0
    config = client.read_config(1)
    client.set_param(1, ParamId.CONFIG, config | ConfigFlag.SYNC_MOTION)
    assert client.read_config(1) == config | ConfigFlag.SYNC_MOTION
    assert client.get_param(1, ParamId.DEF_CUBE_VERSION) == 0x4638  # u16
    assert isinstance(client.get_param(1, ParamId.DEF_ADDRESS), int)  # u8
    assert isinstance(client.get_param(1, ParamId.POS_COUNT), int)  # i32
    assert isinstance(client.get_param(1, ParamId.RAW_CUR), int)  # i16


def test_halt_and_reset(homed):
    homed.halt(5)
    with pytest.raises(ModuleFaultError, match="module 5: .*HALTED") as info:
        homed.check_ok(5)
    assert info.value.module == 5
    assert homed.read_pos_state_dio(5).state & ShortState.NOT_OK
    homed.reset(5)
    assert homed.check_ok(5) & StateFlag.HOME_OK
    homed.halt()
    assert all(homed.read_state(m) & StateFlag.HALTED for m in range(1, 8))
    homed.reset()
    assert not any(homed.read_state(m) & StateFlag.FAULTS for m in range(1, 8))


def test_sync_start(homed):
    homed.set_param(2, ParamId.CONFIG, homed.read_config(2) | ConfigFlag.SYNC_MOTION)
    homed.move_ramp(2, 0.3, 1.0, 2.0)
    homed.idle(0.5)
    assert homed.read_position(2) == 0.0  # held until StartMove
    homed.sync_start()
    wait_until_still(homed, 2)
    assert homed.read_position(2) == pytest.approx(0.3, abs=1e-6)


def test_save_pos_all_and_set_baud_all(homed):
    homed.move_ramp(3, 0.25, 1.0, 2.0)
    wait_until_still(homed, 3)
    homed.save_pos_all()
    assert homed.get_param(3, ParamId.FSAVE_POS) == pytest.approx(0.25, abs=1e-6)
    homed.set_baud_all(BaudRate.BAUD_1M)
    assert homed.read_position(3) == pytest.approx(0.25, abs=1e-6)


def test_watchdog_refreshes_keep_armed_modules_alive_during_waits(open_client):
    client = open_client(faults=["4:no_ack@0"])
    client.home()
    client.set_param(1, ParamId.CONFIG, client.read_config(1) | ConfigFlag.WATCHDOG_ENABLE)
    client.watchdog_period = 0.02
    client.idle(0.5)
    for _ in range(3):  # 3 x 50 ms waiting for a module that never answers
        with pytest.raises(ModuleTimeoutError):
            client.read_position(4)
    assert client.check_ok(1) & StateFlag.HOME_OK
    # Without refreshes the armed watchdog stops the module.
    client.watchdog_period = None
    client.idle(0.2)
    with pytest.raises(ModuleFaultError):
        client.check_ok(1)


def test_refresh_watchdog_by_hand(homed):
    homed.set_param(1, ParamId.CONFIG, homed.read_config(1) | ConfigFlag.WATCHDOG_ENABLE)
    for _ in range(10):
        homed.refresh_watchdog()
        homed.idle(0.03)
    assert homed.check_ok(1)


def test_silent_module_times_out_naming_it(open_client):
    client = open_client(faults=["4:no_ack@0"])
    with pytest.raises(ModuleTimeoutError) as info:
        client.read_arm(range(1, 8))
    assert info.value.module == 4
    assert client.scan() == {m: 0x4638 for m in (1, 2, 3, 5, 6, 7)}


def test_late_ack_from_the_wire_is_consumed_as_stale(homed):
    # 20 µs is shorter than a request/ack round trip on a 1 Mbit/s bus: the ack comes late.
    with pytest.raises(ModuleTimeoutError):
        homed.transact([GetParam(2, ParamId.ACT_POS)], timeout=20e-6)
    homed.move_ramp(2, 0.4, 1.0, 2.0)
    wait_until_still(homed, 2)
    assert homed.read_position(2) == pytest.approx(0.4, abs=1e-6)
    assert homed.stats.stale_acks == 1


def test_tow_error_fault_is_reported(open_client):
    client = open_client(faults=["2:tow_error@0.5"])
    client.home()
    client.idle(0.6)
    reading = client.read_pos_state_dio(2)
    assert reading == ModuleReading(2, 0.0, reading.state, 0)
    assert reading.state & ShortState.NOT_OK
    with pytest.raises(ModuleFaultError, match="TOW_ERROR"):
        client.check_ok(2)


def test_frame_listener_trace_of_a_sim_session(client, clock):
    trace = []
    client.add_frame_listener(trace.append)
    client.read_arm(range(1, 8))
    client.sync_start()
    assert [m.is_rx for m in trace] == [False] * 7 + [True] * 7 + [False]
    times = [m.timestamp for m in trace]
    assert times == sorted(times) and times[-1] <= clock.now()
    assert all(not m.is_extended_id for m in trace)


def test_through_can_bus_entry_point(clock):
    bus = can.Bus(interface="seqrun-sim", channel=f"test-client-sim-{next(_channels)}",
                  clock=clock, ignore_config=True)
    with PowerCubeClient(bus, clock, owns_bus=True) as client:
        assert client.scan(range(1, 8)) == {m: 0x4638 for m in range(1, 8)}
