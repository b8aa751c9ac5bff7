"""Issue 15.1: a host stall must not turn acknowledges that already arrived into a timeout.

The stall is injected in virtual time: after the Nth frame sent, the next ``recv`` first
advances the clock by 60 ms (the host was descheduled while the modules answered).
"""

from __future__ import annotations

import itertools

from projecttree import ROOT
from seqrun.arm.description import load_arm
from seqrun.clock import VirtualClock
from seqrun.service.connection import Connection
from seqrun.results import EXIT_OK
from seqrun.powercube.client import PowerCubeClient
from seqrun.service.runner import run_sequence
from seqrun.sequence.loader import load_sequence
from seqrun.sim.bus import SimBus
from wrapbus import WrapBus

STALL_S = 0.060
_channels = itertools.count()


def stalling_bus(clock: VirtualClock, after_sends: int) -> WrapBus:
    """A simulated arm whose host stalls once, in the first recv after ``after_sends``
    frames were sent."""
    inner = SimBus(channel=f"test-stall-{next(_channels)}", clock=clock)
    state = {"stalled": False}

    def before_recv(timeout):
        if not state["stalled"] and bus.sends >= after_sends:
            state["stalled"] = True
            clock.advance(STALL_S)

    bus = WrapBus(inner, before_recv=before_recv)
    bus.stalled = state
    return bus


def test_a_stall_after_the_seventh_send_of_read_arm_is_no_timeout():
    clock = VirtualClock()
    bus = stalling_bus(clock, after_sends=7)
    client = PowerCubeClient(bus, clock, owns_bus=True)
    try:
        readings = client.read_arm(range(1, 8))
    finally:
        client.close()
    assert bus.stalled["stalled"]
    assert [r.module for r in readings] == list(range(1, 8))
    assert client.stats.timeouts == 0
    assert client.stats.acks_matched == 7


def test_a_run_with_a_host_stall_mid_move_has_no_fault(tmp_path):
    loaded = load_sequence(ROOT / "sequences" / "opsafe.yaml")
    arm = load_arm(loaded.arm_path)
    clock = VirtualClock()
    # ~2000 frames in: well inside the first move (Park -> Totem).
    bus = stalling_bus(clock, after_sends=2000)
    connection = Connection(bus, clock, True, "simulator with a host stall")
    try:
        outcome = run_sequence(loaded, arm, connection, log_dir=tmp_path / "run",
                               confirm=lambda prompt: True, html_report=False)
    finally:
        connection.close()
    assert bus.stalled["stalled"]
    assert outcome.result.fault is None, outcome.result.message
    assert outcome.result.exit_code == EXIT_OK
