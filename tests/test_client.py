"""PowerCubeClient against a scripted fake bus on virtual time."""

from __future__ import annotations

import threading

import can
import pytest

from fakebus import ArmHandler, FakeBus, Reply
from seqrun.clock import VirtualClock
from seqrun.errors import BusError, CodecError, ModuleFaultError, ModuleTimeoutError
from seqrun.powercube.client import DiscardReason, ModuleReading, PowerCubeClient
from seqrun.powercube.codec import (
    BroadcastRequest,
    CommandAck,
    CommandRequest,
    GetParam,
    GetParamAck,
    MotionAck,
    MotionExtAck,
    SetMotion,
    SetParam,
)
from seqrun.powercube.protocol import (
    BaudRate,
    CommandId,
    MotionMode,
    ParamId,
    ShortState,
    StateFlag,
)

TIMEOUT = 0.05


@pytest.fixture
def clock():
    return VirtualClock()


@pytest.fixture
def arm():
    return ArmHandler()


@pytest.fixture
def bus(clock, arm):
    bus = FakeBus(clock, arm)
    yield bus
    bus.shutdown()


@pytest.fixture
def discards():
    return []


@pytest.fixture
def client(bus, clock, discards):
    client = PowerCubeClient(bus, clock, response_timeout=TIMEOUT,
                             on_discard=lambda msg, reason: discards.append((msg, reason)))
    yield client
    client.close()


def sent_frames(bus):
    return [(m.arbitration_id, bytes(m.data)) for m in bus.sent]


def script(*steps):
    """A handler that answers the n-th request with ``steps[n](request)``."""
    calls = iter(steps)
    return lambda request: next(calls)(request)


# ------------------------------------------------------------------------------------
# Matching


def test_get_param_returns_the_matching_value(client, arm):
    arm.positions[3] = 0.5
    assert client.read_position(3) == 0.5
    arm.params[(3, ParamId.ACT_VEL)] = -0.25
    assert client.read_velocity(3) == -0.25
    arm.params[(3, ParamId.CUBE_STATE)] = 0x8002
    assert client.read_state(3) == StateFlag.HOME_OK | StateFlag.RAMP_END


def test_requests_use_standard_ids_and_exact_bytes(client, bus):
    client.move_ramp(2, 1.0, 0.77, 0.8)
    assert sent_frames(bus) == [
        (0x0E2, bytes.fromhex("084FB81E453F")),
        (0x0E2, bytes.fromhex("0850CDCC4C3F")),
        (0x0E2, bytes.fromhex("0B040000803F")),
    ]
    assert all(not m.is_extended_id for m in bus.sent)


def test_move_ramp_waits_for_each_answer_of_its_module_and_returns_the_motion_ack(client, bus):
    ack = client.move_ramp(2, 1.0, 0.5)
    assert ack == MotionAck(2, MotionMode.FRAMP)
    kinds = [kind for kind, _, _ in bus.events]
    # One request in flight per module (issue 9.3); no TargetAcc when acc is None.
    assert kinds == ["send", "recv", "send", "recv"]


def test_requests_to_other_modules_stay_pipelined_one_in_flight_per_module(client, bus):
    requests = [SetParam(1, ParamId.TARGET_VEL, 0.1), SetMotion(1, MotionMode.FRAMP_ACK, 0.2),
                SetParam(2, ParamId.TARGET_VEL, 0.1), SetMotion(2, MotionMode.FRAMP_ACK, 0.2),
                GetParam(3, ParamId.FPOS_STATE_DIO)]
    acks = client.transact(requests)
    assert [a.module for a in acks] == [1, 1, 2, 2, 3]
    in_flight: dict[int, int] = {}
    for kind, _, msg in bus.events:
        module = msg.arbitration_id & 0x1F
        if kind == "send":
            assert in_flight.get(module, 0) == 0, f"two requests in flight to module {module}"
            in_flight[module] = 1
        else:
            in_flight[module] = 0
    # The first three go out at once (one per module), before any answer.
    assert [kind for kind, _, _ in bus.events][:3] == ["send"] * 3


def test_move_ramp_ext_ack_returns_position_and_state(client, arm):
    arm.positions[4] = 0.25
    ack = client.move_ramp(4, 1.0, 0.5, 0.8, ext_ack=True)
    assert ack == MotionExtAck(4, MotionMode.FRAMP_ACK, 0.25, ShortState.RAMP_END, 0)


def test_move_step_and_velocity(client, bus, arm):
    assert client.move_step(2, 0.5, 60) == MotionAck(2, MotionMode.FSTEP)
    ack = client.move_step(2, 0.75, 60, ext_ack=True)
    assert isinstance(ack, MotionExtAck) and ack.position == 0.5
    assert client.move_velocity(5, -0.5) == MotionAck(5, MotionMode.FVEL)
    assert client.move_velocity(5, 0.1, ext_ack=True).mode == MotionMode.FVEL_ACK
    assert bus.sent_requests(SetMotion)[1] == SetMotion(2, MotionMode.FSTEP_ACK, 0.75, 60)
    assert sent_frames(bus)[2] == (0x0E5, bytes.fromhex("0B07000000BF"))


def test_set_param_uses_the_parameter_wire_type(client, bus):
    client.set_param(2, ParamId.CONFIG, 0x09000000)
    client.set_param(2, ParamId.MAX_VEL, 1)  # int given for a float parameter
    client.set_param(2, ParamId.SYNC_TIME, -5)
    assert sent_frames(bus) == [
        (0x0E2, bytes.fromhex("083900000009")),
        (0x0E2, bytes.fromhex("08480000803F")),
        (0x0E2, bytes.fromhex("0866FBFF")),
    ]


def test_invalid_request_sends_nothing(client, bus):
    with pytest.raises(CodecError, match="outside 0..65535"):
        client.transact([GetParam(1, ParamId.ACT_POS),
                         SetParam(1, ParamId.LOAD_DELTA_TIME, 70000)])
    with pytest.raises(CodecError):
        client.move_step(1, 0.0, 70000)
    assert bus.sent == []


def test_ack_from_another_module_is_ignored(bus, client, discards):
    bus.handler = lambda r: [Reply(GetParamAck(3, ParamId.ACT_POS, 9.0), 0.0001),
                             Reply(GetParamAck(2, ParamId.ACT_POS, 1.5), 0.0002)]
    assert client.read_position(2) == 1.5
    assert [reason for _, reason in discards] == [DiscardReason.UNEXPECTED]
    assert discards[0][0].arbitration_id == 0x0A3
    assert client.stats.discarded[DiscardReason.UNEXPECTED] == 1


def test_ack_with_other_parameter_is_ignored(bus, client):
    bus.handler = lambda r: [Reply(GetParamAck(2, ParamId.ACT_VEL, 9.0), 0.0001),
                             Reply(GetParamAck(2, ParamId.ACT_POS, 1.5), 0.0002)]
    assert client.read_position(2) == 1.5


def test_malformed_and_foreign_frames_are_ignored(bus, client, discards):
    def handler(request):
        return [
            Reply((0x0A2, bytes.fromhex("0A3C0000")), 0.0001),  # too short
            Reply((0x0A2, bytes.fromhex("0A11000000FF")), 0.0001),  # unknown param
            Reply((0x0A0, bytes.fromhex("0A3C0000003F")), 0.0001),  # module 0
            Reply((0x123, bytes.fromhex("0A3C")), 0.0001),  # not an ack id
            Reply(can.Message(arbitration_id=0x0A2, data=bytes.fromhex("0A3C0000803F"),
                              is_extended_id=True), 0.0001),  # 29-bit
            Reply(GetParamAck(2, ParamId.ACT_POS, 0.5), 0.0003),
        ]

    bus.handler = handler
    assert client.read_position(2) == 0.5
    reasons = [reason for _, reason in discards]
    assert len(reasons) == 5
    assert sum(r.startswith(DiscardReason.MALFORMED) for r in reasons) == 3
    assert reasons.count(DiscardReason.NOT_AN_ACK) == 2
    assert "needs 6 bytes" in reasons[0]
    assert client.stats.discarded_total == 5


def test_equal_keys_in_one_batch_are_answered_in_order(bus, client):
    values = iter([1.0, 2.0])
    bus.handler = lambda r: [GetParamAck(1, ParamId.ACT_POS, next(values))]
    acks = client.transact([GetParam(1, ParamId.ACT_POS), GetParam(1, ParamId.ACT_POS)])
    assert [a.value for a in acks] == [1.0, 2.0]


def test_command_acks_match_on_byte_0_only(bus, client):
    bus.handler = lambda r: [Reply((0x0A1, b"\x00"))]  # DLC 1, no 0x64
    client.reset(1)
    assert bus.sent_requests() == [CommandRequest(1, CommandId.RESET)]


def test_frame_received_before_the_request_is_never_its_answer(bus, client, clock, discards):
    # An old ack of module 2's ActPos is waiting in the receive queue.
    bus.inject(GetParamAck(2, ParamId.ACT_POS, 9.0))
    assert client.read_position(2) == 0.0
    assert [reason for _, reason in discards] == [DiscardReason.BEFORE_REQUEST]


# ------------------------------------------------------------------------------------
# Timeouts and stale acks


def test_timeout_names_the_module(bus, client, clock):
    bus.handler = lambda r: []
    with pytest.raises(ModuleTimeoutError) as info:
        client.read_position(3)
    assert info.value.module == 3
    assert "ACT_POS" in info.value.what
    assert "module 3" in str(info.value) and "50 ms" in str(info.value)
    assert clock.now() == pytest.approx(TIMEOUT)
    assert client.stats.timeouts == 1


def test_timeout_in_a_batch_names_the_silent_module(bus, client, arm):
    arm.modules.discard(5)
    arm.modules.discard(6)
    with pytest.raises(ModuleTimeoutError) as info:
        client.read_arm(range(1, 8))
    assert info.value.module == 5
    assert "6 did not answer either" in info.value.what


def test_broadcasts_expect_no_ack(bus, client, clock):
    client.halt()
    client.reset(None)
    client.home()
    client.sync_start()
    client.save_pos_all()
    client.set_baud_all(BaudRate.BAUD_1M)
    client.refresh_watchdog()
    assert clock.now() == 0.0  # nothing was waited for
    assert sent_frames(bus) == [(0x100, bytes.fromhex(d)) for d in
                                ["0200", "0000", "0100", "0F00", "0E00", "0903", "0700"]]
    results = client.transact([BroadcastRequest(CommandId.HALT),
                               CommandRequest(1, CommandId.RESET)])
    assert results == [None, CommandAck(1, CommandId.RESET)]


def test_late_ack_is_not_the_answer_of_the_next_request(bus, client, clock):
    # The first read is answered 80 ms late (after its 50 ms timeout) with 1.0;
    # the second read is answered promptly with 2.0.
    bus.handler = script(
        lambda r: [Reply(GetParamAck(2, ParamId.ACT_POS, 1.0), 0.080)],
        lambda r: [Reply(GetParamAck(2, ParamId.ACT_POS, 2.0), 0.001)],
    )
    with pytest.raises(ModuleTimeoutError):
        client.read_position(2)
    assert client.read_position(2) == 2.0
    assert client.stats.stale_acks == 1
    # The second request was sent only once the late ack had been consumed.
    second_send = [t for kind, t, _ in bus.events if kind == "send"][1]
    assert second_send == pytest.approx(0.080)


def test_late_ack_that_never_comes_delays_only_its_own_key(bus, client, clock):
    bus.handler = script(
        lambda r: [],  # ActPos of module 2 never answered
        lambda r: [GetParamAck(2, ParamId.ACT_VEL, 0.25)],
        lambda r: [GetParamAck(2, ParamId.ACT_POS, 2.0)],
    )
    with pytest.raises(ModuleTimeoutError):
        client.read_position(2)
    t_timeout = clock.now()
    assert client.read_velocity(2) == 0.25  # another key: not delayed
    assert clock.now() - t_timeout < 0.002
    assert client.read_position(2) == 2.0  # same key: waits out the quarantine first
    sends = [t for kind, t, _ in bus.events if kind == "send"]
    quarantine = PowerCubeClient.QUARANTINE_TIMEOUTS * TIMEOUT
    assert sends[2] >= t_timeout + quarantine - 1e-9


def test_quarantine_scales_with_a_longer_exchange_timeout(bus, client):
    # Timed out after 300 ms; answered after 500 ms, later than 4 default timeouts.
    bus.handler = script(
        lambda r: [Reply(GetParamAck(2, ParamId.ACT_POS, 1.0), 0.5)],
        lambda r: [Reply(GetParamAck(2, ParamId.ACT_POS, 2.0), 0.001)],
    )
    with pytest.raises(ModuleTimeoutError):
        client.transact([GetParam(2, ParamId.ACT_POS)], timeout=0.3)
    assert client.read_position(2) == 2.0
    assert client.stats.stale_acks == 1


def test_late_ack_arriving_during_a_later_exchange_is_discarded_as_stale(bus, client):
    # Module 2's ActPos times out; its late answer arrives while module 3 is read.
    bus.handler = script(
        lambda r: [Reply(GetParamAck(2, ParamId.ACT_POS, 1.0), 0.052)],
        lambda r: [Reply(GetParamAck(3, ParamId.ACT_POS, 3.0), 0.004)],
    )
    with pytest.raises(ModuleTimeoutError):
        client.read_position(2)
    assert client.read_position(3) == 3.0
    assert client.stats.stale_acks == 1


def test_a_request_held_behind_a_silent_one_to_its_module_is_never_sent(bus, client):
    bus.handler = script(
        lambda r: [],
        lambda r: [Reply(GetParamAck(2, ParamId.ACT_POS, 7.0), 0.001)],
    )
    # Two requests to module 2 in one batch: the second waits for the first's answer
    # (one request in flight per module), which never comes.
    with pytest.raises(ModuleTimeoutError):
        client.transact([GetParam(2, ParamId.ACT_POS), GetParam(2, ParamId.CUBE_STATE)])
    assert len(bus.sent) == 1
    bus.inject(GetParamAck(2, ParamId.ACT_POS, 1.0), at=bus.clock.now() + 0.01)
    # The one late ack is consumed as stale; the next read gets its own answer.
    assert client.read_position(2) == 7.0
    assert client.stats.stale_acks == 1


def test_scan_reports_only_present_modules_in_one_round_trip(bus, client, clock, arm):
    arm.modules = {1, 2, 3, 5}
    assert client.scan() == {1: 0x4638, 2: 0x4638, 3: 0x4638, 5: 0x4638}
    assert len(bus.sent) == 31
    assert clock.now() == pytest.approx(TIMEOUT)  # one timeout, not 27
    assert client.stats.timeouts == 0
    assert client.scan([4], timeout=0.01) == {}


# ------------------------------------------------------------------------------------
# Pipelining, listeners, watchdog


def test_read_arm_sends_all_requests_before_reading_the_first_ack(bus, client, arm):
    arm.positions.update({m: m / 10 for m in range(1, 8)})
    readings = client.read_arm(range(1, 8))
    kinds = [kind for kind, _, _ in bus.events]
    assert kinds == ["send"] * 7 + ["recv"] * 7
    assert [r.module for r in readings] == list(range(1, 8))
    assert readings[2] == ModuleReading(3, pytest.approx(0.3), ShortState.RAMP_END, 0)


def test_read_arm_orders_results_by_request_not_by_arrival(bus, client):
    bus.handler = lambda r: [Reply(GetParamAck(r.module, r.param,
                                               client_value(r.module)), 0.01 - r.module / 1000)]
    readings = client.read_arm([1, 2, 3])
    assert [r.module for r in readings] == [1, 2, 3]
    assert [r.position for r in readings] == [1.0, 2.0, 3.0]
    assert [m.arbitration_id for kind, _, m in bus.events if kind == "recv"] == [
        0x0A3, 0x0A2, 0x0A1]


def client_value(module):
    from seqrun.powercube.codec import PosStateDio

    return PosStateDio(float(module), ShortState(0), 0)


def test_read_pos_state_dio(client, arm):
    arm.positions[6] = 1.25
    arm.state[6] = ShortState.NOT_OK
    assert client.read_pos_state_dio(6) == ModuleReading(6, 1.25, ShortState.NOT_OK, 0)


def test_frame_listeners_see_every_frame(bus, client, clock):
    seen = []
    client.add_frame_listener(seen.append)
    client.read_arm([1, 2])
    client.halt()
    assert [(m.is_rx, m.arbitration_id) for m in seen] == [
        (False, 0x0C1), (False, 0x0C2), (True, 0x0A1), (True, 0x0A2), (False, 0x100)]
    assert [m.timestamp for m in seen[:2]] == [0.0, 0.0]
    assert seen[2].timestamp == pytest.approx(bus.latency)
    assert all(not m.is_extended_id for m in seen)
    client.remove_frame_listener(seen.append)
    client.halt()
    assert len(seen) == 5


def test_failing_listener_does_not_break_the_exchange(client):
    def broken(msg):
        raise RuntimeError("disk full")

    client.add_frame_listener(broken)
    assert client.read_position(1) == 0.0


def test_watchdog_is_refreshed_during_a_long_wait_for_an_ack(bus, client, clock):
    bus.handler = lambda r: [Reply(GetParamAck(2, ParamId.ACT_POS, 0.5), 0.045)]
    client.watchdog_period = 0.02
    assert client.read_position(2) == 0.5
    refreshes = [t for kind, t, m in bus.events
                 if kind == "send" and m.arbitration_id == 0x100]
    assert refreshes == pytest.approx([0.0, 0.02, 0.04])
    assert bytes(bus.sent[0].data) == b"\x07\x00"


def test_watchdog_is_refreshed_while_waiting_out_a_timeout_and_when_idle(bus, client, clock):
    bus.handler = lambda r: []
    client.watchdog_period = 0.01
    with pytest.raises(ModuleTimeoutError):
        client.read_position(2)
    client.idle(0.1)
    times = [t for kind, t, m in bus.events if kind == "send" and m.arbitration_id == 0x100]
    gaps = [b - a for a, b in zip(times, times[1:])]
    assert max(gaps) <= 0.01 + 1e-9
    assert times[-1] >= clock.now() - 0.01
    assert client.stats.watchdog_refreshes == len(times)


def test_service_sends_a_refresh_only_when_due(client, bus, clock):
    assert client.service() is False  # watchdog off
    client.watchdog_period = 0.04
    assert client.service() is True
    assert client.service() is False
    clock.advance(0.03)
    client.refresh_watchdog()  # an explicit refresh restarts the period
    clock.advance(0.02)
    assert client.service() is False
    clock.advance(0.02)
    assert client.service() is True
    assert [bytes(m.data) for m in bus.sent] == [b"\x07\x00"] * 3
    client.watchdog_period = None
    clock.advance(1.0)
    assert client.service() is False


# ------------------------------------------------------------------------------------
# Faults, lifecycle, threads


def test_check_ok_raises_with_decoded_flags(client, arm):
    arm.params[(4, ParamId.CUBE_STATE)] = int(StateFlag.HOME_OK | StateFlag.RAMP_END)
    assert client.check_ok(4) == StateFlag.HOME_OK | StateFlag.RAMP_END
    arm.params[(4, ParamId.CUBE_STATE)] = int(StateFlag.ERROR | StateFlag.TOW_ERROR
                                              | StateFlag.HOME_OK)
    with pytest.raises(ModuleFaultError, match="module 4: ERROR|HOME_OK|TOW_ERROR") as info:
        client.check_ok(4)
    assert info.value.module == 4


def test_raise_for_state():
    PowerCubeClient.raise_for_state(1, StateFlag.CURLIMIT | StateFlag.HOME_OK)
    PowerCubeClient.raise_for_state(1, ShortState.MOTION)
    with pytest.raises(ModuleFaultError, match="HALTED"):
        PowerCubeClient.raise_for_state(1, StateFlag.HALTED)
    with pytest.raises(ModuleFaultError, match="NOT_OK"):
        PowerCubeClient.raise_for_state(2, ShortState.NOT_OK | ShortState.RAMP_END)


def test_send_failure_becomes_bus_error(bus, client):
    bus.fail_next_send = can.CanOperationError("adapter gone")
    with pytest.raises(BusError, match="adapter gone"):
        client.read_position(1)


def test_requests_sent_before_a_send_failure_are_tainted(bus, client):
    values = iter([1.0, 5.0])

    def handler(request):
        if request.module == 1 and bus.fail_next_send is None and len(bus.sent) == 1:
            bus.fail_next_send = can.CanOperationError("tx buffer full")
        return [GetParamAck(request.module, request.param, next(values))]

    bus.handler = handler
    with pytest.raises(BusError, match="tx buffer full"):
        client.transact([GetParam(1, ParamId.ACT_POS), GetParam(2, ParamId.ACT_POS)])
    # The answer to the first (sent) request is still on its way: it must not be taken
    # as the answer to the next read of the same parameter.
    assert client.read_position(1) == 5.0
    assert client.stats.stale_acks == 1


def test_close_is_safe_twice_and_blocks_further_use(bus, clock):
    with PowerCubeClient(bus, clock, owns_bus=True) as client:
        client.read_position(1)
    client.close()
    assert client.closed and bus.shutdown_calls == 1
    with pytest.raises(BusError, match="closed"):
        client.read_position(1)


def test_close_leaves_a_borrowed_bus_open(bus, clock):
    client = PowerCubeClient(bus, clock)
    client.close()
    assert bus.shutdown_calls == 0


def test_bad_settings_are_refused(bus, clock):
    with pytest.raises(ValueError):
        PowerCubeClient(bus, clock, response_timeout=0)
    with pytest.raises(ValueError):
        PowerCubeClient(bus, clock, watchdog_period=-1)


def test_concurrent_callers_each_get_their_own_answer(client, arm):
    arm.positions.update({1: 1.0, 2: 2.0})
    errors = []

    def reader(module):
        try:
            for _ in range(200):
                assert client.read_position(module) == float(module)
                client.service()
        except Exception as exc:  # pragma: no cover - reported below
            errors.append(exc)

    threads = [threading.Thread(target=reader, args=(m,)) for m in (1, 2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    assert client.stats.acks_matched == 400
