"""The dry run's receive path on the simulated wire is the per-frame wire, event for event.

A receive at virtual time (:meth:`SimNetwork._receive_virtual`, what ``seqrun validate``'s
client calls for every acknowledge) runs the wire in one go with the usual steps inlined
(one ready node started without the arbitration search, a module's answer queued in
place, an advance that would do nothing skipped). The reference is the generic wire:
the clock stepped to every event and :meth:`SimNetwork.run_until` called there. Random
cycles of requests (reads, TargetVel writes, FRAMP and FSTEP with positions on the wire,
several requests queued at once, requests to one module back to back, a broadcast) must
give the same frames at the same instants either way.
"""

from __future__ import annotations

import itertools

from hypothesis import given, settings
from hypothesis import strategies as st

from seqrun.clock import VirtualClock
from seqrun.powercube.codec import BroadcastRequest, GetParam, SetMotion, SetParam, encode
from seqrun.powercube.protocol import CommandId, MotionMode, ParamId
from seqrun.sim.module import ModuleOptions
from seqrun.sim.port import SimMessage, SimPort

_channels = itertools.count()


def _request(kind: str, module: int, value: float):
    if kind == "read":
        return GetParam(module, ParamId.FPOS_STATE_DIO)
    if kind == "speed":
        return SetParam(module, ParamId.TARGET_VEL, abs(value) + 0.05)
    if kind == "ramp":
        return SetMotion(module, MotionMode.FRAMP_ACK, value)
    return SetMotion(module, MotionMode.FSTEP_ACK, value, 10)


requests = st.tuples(st.sampled_from(("read", "speed", "ramp", "step")),
                     st.integers(1, 7), st.floats(-1.5, 1.5, allow_nan=False))
cycles = st.lists(st.tuples(st.lists(requests, min_size=1, max_size=9),
                            st.floats(0.0, 0.02), st.booleans()),
                  min_size=1, max_size=12)


def _wire(cycles, *, fast: bool) -> list[tuple]:
    """Every frame delivered, as (time, sender, id, data): each cycle's requests queued at
    once (a refresh broadcast first when asked), the port reading until the answers are in
    (fast) or the clock stepped from event to event (reference); then a pause."""
    clock = VirtualClock()
    port = SimPort(f"fast-lane-{next(_channels)}", clock=clock,
                   options=ModuleOptions(home_ok_at_power_on=True))
    network = port.network
    sniffer = network.attach(name="sniffer")
    try:
        for batch, pause, broadcast in cycles:
            frames = [encode(_request(*r)) for r in batch]
            if broadcast:
                frames.insert(0, encode(BroadcastRequest(CommandId.WATCHDOG_REFRESH, 0)))
            for can_id, data in frames:
                port.send(SimMessage(arbitration_id=can_id, data=data, is_extended_id=False,
                                     is_rx=False))
            answers = len(batch)
            while answers:
                if fast:
                    msg = port.recv(1.0)
                    assert msg is not None
                    answers -= msg.arbitration_id < 0x0C0
                    continue
                event = network._next_event_time()
                assert event is not None
                clock.sleep_until(event)
                network.run_until(event)
                while port.endpoint._inbox:
                    answers -= port.endpoint._inbox.popleft().can_id < 0x0C0
            clock.sleep_until(clock.now() + pause)
        network.run_until(clock.now() + 0.1)
        seen = []
        while sniffer._inbox:
            f = sniffer._inbox.popleft()
            seen.append((f.timestamp, f.sender, f.can_id, f.data))
        return seen
    finally:
        port.shutdown()


@settings(max_examples=40, deadline=None)
@given(cycles)
def test_the_virtual_receive_path_is_the_per_frame_wire(cycles):
    fast, reference = _wire(cycles, fast=True), _wire(cycles, fast=False)
    assert fast == reference
    assert len(fast) >= sum(len(batch) for batch, _, _ in cycles)


def test_positions_on_the_wire_vary_and_still_agree():
    """One long cycle train whose FRAMP targets and answers carry ever new positions (each
    frame's bit length computed afresh)."""
    train = [([("ramp", m, 0.1 * k * (-1) ** m) for m in range(1, 8)]
              + [("read", 1 + k % 7, 0.0)], 0.01, k % 5 == 0) for k in range(1, 30)]
    fast = _wire(train, fast=True)
    assert fast == _wire(train, fast=False)
    assert len({data for _, _, _, data in fast}) > 100
