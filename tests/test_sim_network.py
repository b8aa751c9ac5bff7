"""The simulated wire: exact frame timing, arbitration, delivery, virtual-time waiting."""

from __future__ import annotations

import threading

import pytest

from seqrun.powercube.can_timing import frame_bit_length
from seqrun.clock import RealClock, VirtualClock
from seqrun.sim.arm import SimArm
from seqrun.sim.network import (
    NetworkClosedError,
    SimNetwork,
    TransmitTimeoutError,
    WireFrame,
)

US = 1e-6
GET_VERSION_1 = WireFrame(0x0C1, bytes.fromhex("0A1D"))


def bits(can_id, hexdata):
    return frame_bit_length(can_id, bytes.fromhex(hexdata))


@pytest.fixture
def clock():
    return VirtualClock()


@pytest.fixture
def network(clock):
    return SimNetwork(clock, SimArm(clock, module_latency=100 * US), bitrate=1_000_000)


def drain(endpoint, timeout=0.01):
    frames = []
    while (frame := endpoint.receive(endpoint.network.clock.now() + timeout)) is not None:
        frames.append(frame)
    return frames


def test_request_and_ack_timing_is_exact(clock, network):
    host = network.attach()
    host.send(GET_VERSION_1)
    ack = host.receive(0.01)
    assert (ack.can_id, ack.data) == (0x0A1, bytes.fromhex("0A1D3846"))
    # Request on the wire until its EOF ends (not counting the 3-bit intermission), module
    # latency, then the ack's own wire time.
    request_delivery = (bits(0x0C1, "0A1D") - 3) * US
    expected = request_delivery + 100 * US + (bits(0x0A1, "0A1D3846") - 3) * US
    assert ack.timestamp == pytest.approx(expected, abs=1e-12)
    assert clock.now() == ack.timestamp  # the clock moved exactly to the delivery
    assert network.frames_transmitted == 2
    assert network.busy_time == pytest.approx((bits(0x0C1, "0A1D") + bits(0x0A1, "0A1D3846"))
                                              * US)


def test_nothing_due_advances_clock_by_the_timeout(clock, network):
    host = network.attach()
    assert host.receive(0.25) is None
    assert clock.now() == 0.25


def test_lowest_id_wins_arbitration_between_nodes(clock, network):
    a, b, listener = network.attach(), network.attach(), network.attach()
    a.send(WireFrame(0x300, b"\x01"))
    b.send(WireFrame(0x200, b"\x02"))
    b.send(WireFrame(0x7FF, b"\x03"))
    a.send(WireFrame(0x100 + 0x500, b"\x04"))  # 0x600, queued behind 0x300 at node a
    order = [f.can_id for f in drain(listener)]
    assert order == [0x200, 0x300, 0x600, 0x7FF]


def test_standard_frame_beats_extended_with_same_base_id(clock, network):
    a, b, listener = network.attach(), network.attach(), network.attach()
    a.send(WireFrame(0x123 << 18, b"", is_extended=True))
    b.send(WireFrame(0x123, b""))
    assert [(f.can_id, f.is_extended) for f in drain(listener)] == [
        (0x123, False), (0x123 << 18, True)]


def test_each_node_sends_in_order(clock, network):
    host, listener = network.attach(), network.attach()
    host.send(WireFrame(0x400, b""))
    host.send(WireFrame(0x010, b""))
    assert [f.can_id for f in drain(listener)] == [0x400, 0x010]


def test_acks_overtake_queued_requests(clock, network):
    host = network.attach(receive_own=True)
    for module in range(1, 8):
        host.send(WireFrame(0x0C0 + module, bytes.fromhex("0A62")))
    order = [f.can_id for f in drain(host)]
    # The ack of module 1 (ready 100 us after its request) wins against the host's
    # later requests (0x0A1 < 0x0C3); the bus never idles except for the last latency.
    assert order.index(0x0A1) < order.index(0x0C7)
    assert sorted(order) == sorted([0x0C0 + m for m in range(1, 8)]
                                   + [0x0A0 + m for m in range(1, 8)])
    assert network.frames_transmitted == 14


def test_endpoints_see_each_other_but_not_themselves(clock, network):
    a, b = network.attach(), network.attach()
    a.send(WireFrame(0x321, b"\xAA"))
    assert b.receive(0.01).data == b"\xAA"
    assert a.receive(0.01) is None


def test_extended_and_remote_frames_do_not_reach_the_modules(clock, network):
    host = network.attach()
    host.send(WireFrame(0x0C1, bytes.fromhex("0A1D"), is_extended=True))
    host.send(WireFrame(0x0C1, b"", is_remote=True, dlc=2))
    assert drain(host) == []
    assert network.frames_transmitted == 2


def test_full_transmit_queue_waits_for_the_wire(clock, network):
    host = network.attach(tx_queue_size=1)
    host.send(WireFrame(0x500, bytes(8)))
    host.send(WireFrame(0x500, bytes(8)))  # waits until the first one is on the wire
    assert clock.now() == 0.0  # the first frame started at once: no wait needed
    host.send(WireFrame(0x500, bytes(8)))
    assert clock.now() > 100 * US
    with pytest.raises(TransmitTimeoutError):
        host.send(WireFrame(0x500, bytes(8)), timeout=0.0)


def test_bad_frames_and_closed_endpoints(clock, network):
    host = network.attach()
    with pytest.raises(ValueError, match="at most 8 data bytes"):
        host.send(WireFrame(0x100, bytes(9)))
    with pytest.raises(ValueError, match="standard CAN id"):
        host.send(WireFrame(0x800, b""))
    host.close()
    host.close()
    with pytest.raises(NetworkClosedError):
        host.send(GET_VERSION_1)
    with pytest.raises(NetworkClosedError):
        host.receive(None)


def test_real_time_threads_share_the_wire():
    clock = RealClock()
    network = SimNetwork(clock, SimArm(clock))
    sender, listener = network.attach(), network.attach()
    received = []

    def listen():
        while len(received) < 10:
            frame = listener.receive(clock.now() + 2.0)
            if frame is None:
                break
            received.append(frame)

    thread = threading.Thread(target=listen)
    thread.start()
    start = clock.now()
    for _ in range(5):
        sender.send(GET_VERSION_1)  # 5 requests + 5 acks reach the listener
    thread.join(5.0)
    # The interleaving depends on how fast this thread sends; the set does not.
    assert sorted(f.can_id for f in received) == [0x0A1] * 5 + [0x0C1] * 5
    assert received[0].can_id == 0x0C1
    assert all(start < f.timestamp <= clock.now() for f in received)
    stamps = [f.timestamp for f in received]
    assert stamps == sorted(stamps)
