"""Simulator fidelity found by independent drivers: GetExtended on the SET identifier,
modules that power on homed, a watchdog armed by the first addressed refresh — and the
switches reachable from every place a simulator is made."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time

import can
import pytest

from seqrun.clock import VirtualClock
from seqrun.service.connection import open_connection
from seqrun.errors import UserInputError
from seqrun.powercube.codec import (
    BroadcastRequest,
    CommandRequest,
    GetParam,
    GetParamAck,
    decode_ack,
    encode,
)
from seqrun.powercube.protocol import CommandId, ConfigFlag, ParamId, StateFlag
from seqrun.sim.arm import SimArm
from seqrun.sim.bus import SimBus
from seqrun.sim.module import ModuleOptions, SimModule
from seqrun.sim.options import module_options

F = StateFlag


@pytest.fixture
def clock():
    return VirtualClock()


# -- GetExtended on the SET identifier (KTH driver's probe of module 1) ----------------------

def test_get_extended_on_the_set_id_is_answered_on_the_ack_id(clock):
    arm = SimArm(clock)
    (reply,) = arm.handle_frame(0x0E1, bytes([0x0A, ParamId.DEF_CUBE_VERSION]))
    assert reply.can_id == 0x0A1
    assert decode_ack(reply.can_id, reply.data) == GetParamAck(
        1, ParamId.DEF_CUBE_VERSION, 0x4638)
    # the same answer as on the GET id
    (on_get,) = arm.handle_frame(*encode(GetParam(1, ParamId.DEF_CUBE_VERSION)))
    assert (on_get.can_id, on_get.data) == (reply.can_id, reply.data)


def test_get_extended_on_the_set_id_over_the_simulated_wire(clock):
    with SimBus("set-id-probe", clock=clock, ignore_config=True) as bus:
        bus.send(can.Message(arbitration_id=0x0E7, data=[0x0A, ParamId.ACT_POS],
                             is_extended_id=False))
        msg = bus.recv(0.01)
        assert msg is not None and msg.arbitration_id == 0x0A7
        assert decode_ack(msg.arbitration_id, bytes(msg.data)) == GetParamAck(
            7, ParamId.ACT_POS, 0.0)


# -- HOME_OK at power-on --------------------------------------------------------------------

def test_default_modules_power_on_not_homed(clock):
    assert all(not s & F.HOME_OK for s in SimArm(clock).states().values())


def test_home_ok_at_power_on_through_simbus_kwargs(clock):
    with SimBus("homed-at-boot", clock=clock, home_ok_at_power_on="true",
                ignore_config=True) as bus:
        assert all(s & F.HOME_OK for s in bus.arm.states().values())


def test_bad_switch_values_are_refused_by_name(clock):
    with pytest.raises(can.CanInitializationError, match="home_ok_at_power_on: expected"):
        SimBus("bad-switch", clock=clock, home_ok_at_power_on="maybe", ignore_config=True)
    with pytest.raises(ValueError, match="unknown simulator option 'homed'"):
        module_options({"homed": True})
    assert module_options({"watchdog_timeout": "0.1"}).watchdog_timeout == 0.1


def test_switches_reach_the_in_process_simulator_through_bus_kwargs():
    connection = open_connection(bus_kwargs={"home_ok_at_power_on": True},
                                 clock=VirtualClock())
    try:
        assert connection.is_simulator
        assert all(s & F.HOME_OK for s in connection.bus.arm.states().values())
    finally:
        connection.close()
    with pytest.raises(UserInputError, match="--bus-kwargs port: the built-in simulator"):
        open_connection(bus_kwargs={"port": 1}, clock=VirtualClock())


# -- watchdog armed by the first addressed refresh ---------------------------------------------

def homed_module(clock, **options) -> SimModule:
    module = SimModule(1, clock, options=ModuleOptions(watchdog_timeout=0.05, **options))
    module.handle(CommandRequest(1, CommandId.HOME))
    return module


def test_default_watchdog_needs_the_config_bit_and_any_refresh_arms_it(clock):
    module = homed_module(clock)
    module.handle(CommandRequest(1, CommandId.WATCHDOG_REFRESH))  # addressed, bit clear
    clock.advance(0.2)
    assert not module.state().is_fault  # not armed: Config says no watchdog


def test_addressed_refresh_arms_the_watchdog_when_switched_on(clock):
    module = homed_module(clock, addressed_refresh_arms_watchdog=True)
    module.handle(BroadcastRequest(CommandId.WATCHDOG_REFRESH))
    clock.advance(0.2)
    assert not module.state().is_fault  # a broadcast does not arm it
    module.handle(CommandRequest(1, CommandId.WATCHDOG_REFRESH))  # armed, bit set
    assert module.parameter(ParamId.CONFIG) & ConfigFlag.WATCHDOG_ENABLE
    for _ in range(5):  # broadcasts keep it alive
        clock.advance(0.04)
        module.handle(BroadcastRequest(CommandId.WATCHDOG_REFRESH))
    assert not module.state().is_fault
    clock.advance(0.06)
    assert module.state() & F.COMM_ERROR and module.state() & F.HALTED


# -- the same switches from `seqrun sim serve` ----------------------------------------------

@pytest.mark.slow  # a real-time subprocess: 50 ms watchdog timing
def test_sim_serve_switches():
    process = subprocess.Popen(
        [sys.executable, "-m", "seqrun", "sim", "serve", "--port", "0",
         "--home-ok-at-power-on", "--addressed-refresh-arms-watchdog"],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        # The whole banner, read here: communicate(timeout=...) below reads the pipe's file
        # descriptor and would miss lines already buffered by readline().
        banner = "".join(iter(process.stdout.readline, "Ctrl-C to stop.\n"))
        port = int(re.search(r"127\.0\.0\.1:(\d+)", banner).group(1))
        with can.Bus(interface="socketcand", host="127.0.0.1", port=port, channel="can0",
                     ignore_config=True) as bus:
            bus.send(can.Message(arbitration_id=0x0E2, data=[CommandId.WATCHDOG_REFRESH],
                                 is_extended_id=False))
            bus.send(can.Message(arbitration_id=0x0C2, data=[0x0A, ParamId.CUBE_STATE],
                                 is_extended_id=False))
            acks = []
            while len(acks) < 2:
                msg = bus.recv(2.0)
                assert msg is not None
                acks.append(decode_ack(msg.arbitration_id, bytes(msg.data)))
            assert acks[1].value & F.HOME_OK  # homed at power-on
            # no further refresh: the armed watchdog stops the module 50 ms later
            bus.send(can.Message(arbitration_id=0x0C2, data=[0x0A, ParamId.CUBE_STATE],
                                 is_extended_id=False))
            time.sleep(0.2)
            bus.send(can.Message(arbitration_id=0x0C2, data=[0x0A, ParamId.CUBE_STATE],
                                 is_extended_id=False))
            states = [decode_ack(m.arbitration_id, bytes(m.data)).value
                      for m in iter(lambda: bus.recv(1.0), None)]
            assert states[-1] & F.COMM_ERROR
        process.send_signal(signal.SIGINT)
        output, _ = process.communicate(timeout=5)
        assert "switch home_ok_at_power_on=True" in banner + output
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
