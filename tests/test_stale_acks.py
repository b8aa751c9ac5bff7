"""Frames that are not the answer, arriving in the middle of a run's control cycles.

The client-level rules (tests/test_client.py: a late ack of a timed-out request, an ack from
another module or for another parameter, malformed frames, foreign and 29-bit ids, frames
queued before the request) are not repeated here. These tests put such frames on the wire
of a running executor - opsafe.yaml at virtual time, through ``run_sequence`` - from a
second node on the same simulated bus, timed to arrive while a cycle collects its answers,
and check that none of them is ever taken as an answer: the run passes, the measured
positions never show their bogus values, every frame is discarded for the right reason,
counted in ``client.stats`` and logged in the run's trace.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import can
import numpy as np
import pytest

from projecttree import ROOT, shipped_arm
from runfolder import RunFolder
from seqrun.clock import VirtualClock
from seqrun.service.connection import Connection, open_connection
from seqrun.powercube.client import DiscardReason, PowerCubeClient
from seqrun.powercube.codec import GetParamAck, MotionExtAck, PosStateDio, encode
from seqrun.powercube.protocol import MotionMode, ParamId, ShortState
from seqrun.service.runner import run_sequence
from seqrun.sequence.loader import load_sequence
from seqrun.sim.bus import SimBus

ARM = shipped_arm()
CYCLE = 1.0 / ARM.control.cycle_hz
TIMEOUT = ARM.can.response_timeout_s
#: 1.0 rad in module coordinates: far from anywhere j4 or j7 is during opsafe.
BOGUS_RAD = 1.0


def message(frame: tuple[int, bytes], *, extended: bool = False, remote: bool = False
            ) -> can.Message:
    can_id, data = frame
    if remote:
        return can.Message(arbitration_id=can_id, is_remote_frame=True, dlc=len(data),
                           is_extended_id=extended)
    return can.Message(arbitration_id=can_id, data=data, is_extended_id=extended)


class Run:
    """opsafe.yaml on a fresh simulated arm, with hooks on the executor and its client."""

    def __init__(self, tmp_path: Path, *, bus_wrapper=None, on_send=None, on_event=None):
        self.folder = tmp_path / "run"
        self.discards: list[tuple[float, can.Message, str]] = []
        loaded = load_sequence(ROOT / "sequences" / "opsafe.yaml")
        self.clock = VirtualClock()
        connection = open_connection(force_sim=True, clock=self.clock)
        sim_bus = connection.bus
        #: A second node on the same wire.
        self.intruder = SimBus(channel=sim_bus.channel, clock=self.clock)
        bus = bus_wrapper(sim_bus, self.clock) if bus_wrapper else sim_bus
        conn = Connection(bus, self.clock, True, connection.description)

        def hook(executor) -> None:
            self.executor = executor
            self.client: PowerCubeClient = executor.client
            self.client.on_discard = lambda msg, reason: self.discards.append(
                (self.clock.now(), msg, reason))
            if on_send is not None:
                self.client.add_frame_listener(lambda msg: msg.is_rx or on_send(self, msg))
            if on_event is not None:
                executor.listeners.append(lambda event: on_event(self, event))

        try:
            self.outcome = run_sequence(loaded, ARM, conn, log_dir=self.folder,
                                        confirm=lambda prompt: True, on_executor=hook,
                                        html_report=False)
        finally:
            self.intruder.shutdown()
            if bus is not sim_bus:
                bus.shutdown()
            sim_bus.shutdown()
        self.events = RunFolder(self.folder).events()
        self.trace = RunFolder(self.folder).trace()

    def inject(self, *frames: can.Message) -> None:
        for frame in frames:
            self.intruder.send(frame)

    def measured(self) -> list[tuple[float, np.ndarray]]:
        """(t, joints in user degrees) of every reading the executor used."""
        out = []
        for e in self.events:
            if e["type"] == "setpoint":
                out.append((e["t"], np.array(e["measured_deg"])))
            elif e["type"] == "measurement":
                out.append((e["t"], np.array(e["joints_deg"])))
        return out

    def assert_passed(self) -> None:
        result = self.outcome.result
        assert (result.status, result.exit_code) == ("passed", 0), result.message
        assert self.outcome.report["checkpoints"][0]["status"] == "passed"
        assert not [m for m in self.trace if m.arbitration_id == 0x100 and m.data[:1] == b"\x02"]

    def assert_readings_continuous(self) -> None:
        """No bogus reading: j7 (never commanded) reads 0 throughout, and no joint jumps
        between two readings (1 rad in module coordinates would be a jump of over 10°;
        30°/s for one cycle plus a lost answer's timeout is under 2°)."""
        readings = self.measured()
        assert all(abs(q[6]) < 1e-6 for _, q in readings)
        for (t0, q0), (t1, q1) in itertools.pairwise(readings):
            assert np.max(np.abs(q1 - q0)) < 2.0, (t0, t1, q0, q1)


# ----------------------------------------------------------------------------------------
# Foreign, wrong-module and malformed frames in the middle of cycles


def _bad_frames_during_a_move(module: int) -> list[can.Message]:
    """Sent while the cycle's motion command to ``module`` (a moving joint) awaits its
    extended acknowledge."""
    ext_ack = encode(MotionExtAck(module, MotionMode.FRAMP_ACK, BOGUS_RAD, ShortState(0), 0))
    return [
        # From another module: j7 is never commanded, nobody waits for its motion ack.
        message(encode(MotionExtAck(7, MotionMode.FRAMP_ACK, BOGUS_RAD, ShortState(0), 0))),
        # The moving module, but for a read nobody made (it gets motion commands).
        message(encode(GetParamAck(module, ParamId.FPOS_STATE_DIO,
                                   PosStateDio(BOGUS_RAD, ShortState.NOT_OK, 0)))),
        # The awaited id and command bytes, wrong length: malformed, not an answer.
        message((ext_ack[0], ext_ack[1][:3])),
        # A valid-looking answer on a 29-bit id, as a remote frame, and on a foreign id
        # (below the acknowledge range, so it wins arbitration against the requests).
        message(ext_ack, extended=True),
        message(ext_ack, remote=True),
        message((0x05A, ext_ack[1])),
    ]


def _bad_frames_during_a_wait(module: int) -> list[can.Message]:
    """Sent while the cycle's FPosStateDio read of ``module`` awaits its answer."""
    good = encode(GetParamAck(module, ParamId.FPOS_STATE_DIO,
                              PosStateDio(BOGUS_RAD, ShortState(0), 0)))
    return [
        message((good[0], good[1][:4])),                      # malformed: 4 of 8 bytes
        message(encode(GetParamAck(9, ParamId.FPOS_STATE_DIO,  # a module the arm lacks
                                   PosStateDio(BOGUS_RAD, ShortState(0), 0)))),
        message(encode(GetParamAck(module, ParamId.ACT_POS, BOGUS_RAD))),  # not asked for
        message((0x05A, b"\x0a\x62")),                        # foreign id
    ]


#: Reasons the client gives, per frame of the two bursts above (in send order).
MOVE_REASONS = [DiscardReason.UNEXPECTED, DiscardReason.UNEXPECTED, DiscardReason.MALFORMED,
                DiscardReason.NOT_AN_ACK, DiscardReason.NOT_AN_ACK, DiscardReason.NOT_AN_ACK]
WAIT_REASONS = [DiscardReason.MALFORMED, DiscardReason.UNEXPECTED, DiscardReason.UNEXPECTED,
                DiscardReason.NOT_AN_ACK]


def test_foreign_wrong_module_and_malformed_frames_mid_cycle_are_never_answers(tmp_path):
    # Bursts: during move 1 (3 s), during move 2 (10 s), during the dwell (14 s); each sent
    # by the second node the moment the run's client sends the request they imitate the
    # answer of, so they reach the client while that cycle collects its answers.
    bursts: dict[str, float] = {}

    def on_send(run: Run, msg: can.Message) -> None:
        t = run.clock.now()
        motion_to_4 = msg.arbitration_id == 0x0E4 and msg.data[:1] == b"\x0b"
        read_of_4 = msg.arbitration_id == 0x0C4 and bytes(msg.data) == b"\x0a\x62"
        for name, start, matches, frames in (
                ("move1", 3.0, motion_to_4, _bad_frames_during_a_move),
                ("move2", 10.0, motion_to_4, _bad_frames_during_a_move),
                ("dwell", 14.0, read_of_4, _bad_frames_during_a_wait)):
            if name not in bursts and t >= start and matches:
                bursts[name] = t
                run.inject(*frames(4))

    run = Run(tmp_path, on_send=on_send)
    run.assert_passed()
    assert sorted(bursts) == ["dwell", "move1", "move2"]
    run.assert_readings_continuous()
    # Every injected frame discarded, for its reason, within the cycle it was sent in:
    # none was still queued when a later exchange began ("received before the request").
    for name, t_burst in bursts.items():
        expected = WAIT_REASONS if name == "dwell" else MOVE_REASONS
        got = [(t, reason) for t, _, reason in run.discards if t_burst <= t < t_burst + CYCLE]
        assert [r.split(":")[0] for _, r in got] == expected, (name, got)
        assert all(t < t_burst + 0.003 for t, _ in got)
    assert not [d for d in run.discards if d[2] == DiscardReason.BEFORE_REQUEST]
    stats = run.client.stats
    assert stats.discarded_total == len(run.discards) == 2 * len(MOVE_REASONS) + len(WAIT_REASONS)
    assert stats.discarded[DiscardReason.MALFORMED] == 3 and stats.timeouts == 0
    # The run's trace logs them as received frames.
    received = {(m.arbitration_id, m.is_extended_id, m.is_remote_frame, bytes(m.data))
                for m in run.trace if m.is_rx}
    for frame in _bad_frames_during_a_move(4) + _bad_frames_during_a_wait(4):
        assert (frame.arbitration_id, frame.is_extended_id, frame.is_remote_frame,
                bytes(frame.data)) in received


# ----------------------------------------------------------------------------------------
# A late answer to a read that timed out


class LosingBus(can.BusABC):
    """The run's view of the simulated bus, losing the acknowledges ``lose(msg)`` picks (as
    if the frame never reached the adapter); everything else passes through unchanged."""

    def __init__(self, inner: SimBus, clock: VirtualClock, lose) -> None:
        self.inner = inner
        self.clock = clock
        self.lose = lose
        self.lost: list[can.Message] = []
        super().__init__(channel=inner.channel)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.inner.send(msg, timeout)

    def recv(self, timeout: float | None = None) -> can.Message | None:
        deadline = None if timeout is None else self.clock.now() + timeout
        while True:
            wait = None if deadline is None else max(0.0, deadline - self.clock.now())
            msg = self.inner.recv(wait)
            if msg is None or not self.lose(msg):
                return msg
            self.lost.append(msg)

    def _recv_internal(self, timeout):  # pragma: no cover - recv is overridden
        return self.recv(timeout), False

    def shutdown(self) -> None:
        super().shutdown()


def _first_read_of_7_after(t0: float):
    state = {"done": False}

    def lose(msg: can.Message) -> bool:
        if (not state["done"] and msg.arbitration_id == 0x0A7 and msg.data[:2] == b"\x0a\x62"
                and msg.timestamp >= t0):
            state["done"] = True
            return True
        return False
    return lose


@pytest.mark.parametrize("t_loss", [3.0, 14.0], ids=["during-a-move", "during-the-dwell"])
def test_late_answer_of_a_timed_out_read_is_stale_and_never_used(tmp_path, t_loss):
    """Module 7's FPosStateDio answer is lost once; a bogus copy of it (1 rad, NOT_OK)
    arrives after the timeout, while the retry (ActPos + CubeState) collects its answers.
    It is consumed as the stale answer of the timed-out read - never as an answer - and
    that ends the quarantine, so the next cycle reads FPosStateDio again."""
    wrappers: list[LosingBus] = []
    late: dict[str, float] = {}
    bogus = message(encode(GetParamAck(7, ParamId.FPOS_STATE_DIO,
                                       PosStateDio(BOGUS_RAD, ShortState.NOT_OK, 0))))

    def wrap(bus, clock):
        wrappers.append(LosingBus(bus, clock, _first_read_of_7_after(t_loss)))
        return wrappers[0]

    def on_event(run: Run, event: dict) -> None:
        if event["type"] == "retry" and "late" not in late:
            late["late"] = run.clock.now()
            run.inject(bogus)

    run = Run(tmp_path, bus_wrapper=wrap, on_event=on_event)
    run.assert_passed()
    (lost,) = wrappers[0].lost
    retries = [e for e in run.events if e["type"] == "retry"]
    assert [(e["modules"], e["what"]) for e in retries] == [([7], "read")]
    # The retry came one response timeout after the lost read was sent.
    sent = [m for m in run.trace if not m.is_rx and m.arbitration_id == 0x0C7]
    t_read = max(m.timestamp for m in sent if m.timestamp < lost.timestamp)
    assert retries[0]["t"] == pytest.approx(t_read + TIMEOUT, abs=1e-6)
    # The bogus late answer: discarded as stale, in the retry's exchange, once.
    stale = [(t, m) for t, m, reason in run.discards if reason == DiscardReason.STALE]
    assert len(stale) == 1 and run.client.stats.stale_acks == 1
    t_stale, msg = stale[0]
    assert bytes(msg.data) == bytes(bogus.data)
    assert late["late"] <= t_stale < late["late"] + 0.002
    # Never used: j7 reads 0 throughout, no NOT_OK was acted on.
    run.assert_readings_continuous()
    # The retry read the other path; with the taint consumed, FPosStateDio is back next cycle.
    after = [(m.timestamp, m.data[1]) for m in sent if m.timestamp > t_read]
    assert [p for _, p in after[:2]] == [ParamId.ACT_POS, ParamId.CUBE_STATE]
    assert after[2][1] == ParamId.FPOS_STATE_DIO and after[2][0] < t_stale + CYCLE + 0.003
    # The loop did not stall: one cycle plus the one timeout, never a quarantine.
    motion = sorted({m.timestamp for m in run.trace if not m.is_rx
                     and 0x0E0 < m.arbitration_id < 0x100 and m.data[:1] == b"\x0b"})
    assert max(b - a for a, b in itertools.pairwise(motion)) <= CYCLE + TIMEOUT + 0.003


def test_a_lost_read_without_a_late_answer_keeps_the_other_path_for_the_quarantine(tmp_path):
    """No late answer comes: FPosStateDio of module 7 stays in quarantine for
    QUARANTINE_TIMEOUTS response timeouts, read meanwhile by ActPos + CubeState every cycle
    without waiting, then FPosStateDio again."""
    wrappers: list[LosingBus] = []

    def wrap(bus, clock):
        wrappers.append(LosingBus(bus, clock, _first_read_of_7_after(3.0)))
        return wrappers[0]

    run = Run(tmp_path, bus_wrapper=wrap)
    run.assert_passed()
    run.assert_readings_continuous()
    assert run.client.stats.stale_acks == 0 and run.client.stats.timeouts == 0
    (lost,) = wrappers[0].lost
    reads = [(m.timestamp, m.data[1]) for m in run.trace
             if not m.is_rx and m.arbitration_id == 0x0C7]
    t_read = max(t for t, _ in reads if t < lost.timestamp)
    quarantine_end = t_read + TIMEOUT + PowerCubeClient.QUARANTINE_TIMEOUTS * TIMEOUT
    during = [p for t, p in reads if t_read < t < quarantine_end - 1e-9]
    assert during and set(during) == {ParamId.ACT_POS, ParamId.CUBE_STATE}
    # Every cycle of the quarantine read module 7 (ActPos, then CubeState once ActPos is
    # answered: one request in flight per module; a pair may straddle the window's end).
    cycles = (quarantine_end - (t_read + TIMEOUT)) / CYCLE
    act, state = during.count(ParamId.ACT_POS), during.count(ParamId.CUBE_STATE)
    assert abs(act - cycles) <= 1 and abs(act - state) <= 1, (act, state, cycles)
    # (the CubeState that completes the last pair of the quarantine may come just after it)
    first_after = next((t, p) for t, p in reads
                       if t >= quarantine_end - 1e-9 and p != ParamId.CUBE_STATE)
    assert first_after[1] == ParamId.FPOS_STATE_DIO and first_after[0] < quarantine_end + CYCLE
