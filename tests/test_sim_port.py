"""SimPort: the simulator without python-can (the dry run's bus) is the same wire as SimBus."""

from __future__ import annotations

import itertools
from pathlib import Path

import can
import pytest

import seqrun.service.dryrun as dryrun_module
from seqrun.arm.description import load_arm
from seqrun.clock import VirtualClock
from seqrun.service.connection import open_connection
from seqrun.service.dryrun import dry_run
from seqrun.powercube.client import PowerCubeClient
from seqrun.powercube.codec import GetParam, encode
from seqrun.powercube.protocol import ParamId
from seqrun.sequence.loader import load_sequence
from seqrun.sim.bus import SimBus
from seqrun.sim.port import SimMessage, SimPort, SimSetupError, get_network
from seqrun.arm.poses import pose_joints_deg

ROOT = Path(__file__).resolve().parents[1]
_names = itertools.count()

#: can.Message's fields that a reader of frames uses (the client, the run log's writer).
FIELDS = ("timestamp", "arbitration_id", "is_extended_id", "is_remote_frame", "is_error_frame",
          "channel", "dlc", "data", "is_fd", "is_rx", "bitrate_switch", "error_state_indicator")


@pytest.fixture
def channel():
    return f"test-sim-port-{next(_names)}"


def test_a_sim_message_has_the_fields_and_defaults_of_a_python_can_message():
    for kwargs in ({}, {"arbitration_id": 0x0C4, "data": b"\x0a\x1d", "is_extended_id": False,
                        "is_rx": False, "timestamp": 1.5, "channel": "arm0"},
                   {"arbitration_id": 0x123, "is_remote_frame": True, "dlc": 4}):
        light, real = SimMessage(**kwargs), can.Message(**kwargs)
        assert {f: getattr(light, f) for f in FIELDS} == {f: getattr(real, f) for f in FIELDS}
        assert type(light.data) is type(real.data) is bytearray


def test_a_port_and_a_python_can_bus_share_one_wire(channel):
    clock = VirtualClock()
    port = SimPort(channel, clock=clock)
    bus = SimBus(channel, clock=clock)
    try:
        assert get_network(channel) is port.network is bus.network
        can_id, data = encode(GetParam(4, ParamId.DEF_CUBE_VERSION))
        port.send(SimMessage(arbitration_id=can_id, data=data, is_extended_id=False))
        seen = bus.recv(0.01)   # the request, as the other host sees it
        assert (seen.arbitration_id, bytes(seen.data)) == (can_id, data)
        ack = port.recv(0.01)
        other = bus.recv(0.01)
        assert isinstance(ack, SimMessage) and isinstance(other, can.Message)
        assert {f: getattr(ack, f) for f in FIELDS} == {f: getattr(other, f) for f in FIELDS}
        assert ack.arbitration_id == 0x0A4 and ack.is_rx and ack.timestamp == clock.now()
    finally:
        port.shutdown()
        bus.shutdown()
    with pytest.raises(LookupError):
        get_network(channel)


def test_a_port_refuses_what_a_sim_bus_refuses(channel):
    with SimPort(channel, clock=VirtualClock()) as port:
        with pytest.raises(ValueError, match="CAN FD"):
            port.send(SimMessage(arbitration_id=1, is_fd=True, data=bytes(12)))
        with pytest.raises(ValueError, match="standard CAN id"):
            port.send(SimMessage(arbitration_id=0x800, is_extended_id=False))
        with pytest.raises(SimSetupError, match="another clock"):
            SimPort(channel, clock=VirtualClock())
    with pytest.raises(SimSetupError, match="unknown kind"):
        SimPort(channel, faults=["1:boom@0"])


def test_the_client_builds_the_messages_its_bus_takes(channel):
    clock = VirtualClock()
    with SimPort(channel, clock=clock) as port:
        client = PowerCubeClient(port, clock)
        sent = []
        client.add_frame_listener(sent.append)
        assert client.get_param(3, ParamId.DEF_CUBE_VERSION) is not None
        assert [type(m) for m in sent] == [SimMessage, SimMessage]
        assert [m.is_rx for m in sent] == [False, True]


def _opsafe_dry_run():
    loaded = load_sequence(ROOT / "sequences" / "opsafe.yaml")
    arm = load_arm(loaded.arm_path)
    start = pose_joints_deg("park", loaded.pose_path or loaded.poses_dir)
    return dry_run(loaded, arm, start).as_dict()


def test_the_dry_run_on_a_port_is_the_dry_run_on_a_python_can_bus(monkeypatch):
    """Same wire, same frames: every simulated figure of the report is identical."""
    on_port = _opsafe_dry_run()

    def python_can_connection(**kwargs):
        assert kwargs.pop("python_can") is False   # what the dry run asks for
        return open_connection(**kwargs)

    monkeypatch.setattr(dryrun_module, "open_connection", python_can_connection)
    on_bus = _opsafe_dry_run()
    for report in (on_port, on_bus):
        del report["wall_s"], report["speedup"]
    assert on_port["passed"] and on_port["simulated_s"] > 10
    assert on_port == on_bus
