"""Throughput of the PowerCube codec and of ack matching, against the 1 Mbit/s bus.

For three realistic exchanges (a pipelined 7-module FPosStateDio read, a pipelined
moveRamp, a 7-module step-with-ack cycle) it measures, per frame and on one core:

- encode:  ``encode()`` of every request and every acknowledge;
- decode:  ``decode_request()`` of the requests and ``decode_ack()`` of the acks. The codec
           keeps the frames it decoded (a bus repeats them: every read of a module at
           rest), so two figures: "new" frames (its memo emptied before each round: a
           moving arm's positions) and "seen" frames (the memo's hits);
- client:  what the client does per frame: encode a request, or decode an ack and match
           it (``ack_key`` + pending-table lookup);

and compares with how many of the same frames a 1 Mbit/s bus can carry (exact bit length
from ``seqrun.powercube.can_timing`` when present: stuff bits and 3-bit intermission included).
The last row runs the whole ``PowerCubeClient.read_arm`` over a bus that answers
instantly (python-can message objects included). Goal: every path at least 5x the bus
frame rate.

Run: ``.venv/bin/python bench/bench_codec.py``
"""

from __future__ import annotations

import sys
import time
from collections import deque
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from seqrun.powercube import codec  # noqa: E402
from seqrun.powercube.codec import (  # noqa: E402
    GetParam,
    GetParamAck,
    MotionAck,
    MotionExtAck,
    PosStateDio,
    SetMotion,
    SetParam,
    SetParamAck,
    ack_key,
    decode_ack,
    decode_request,
    encode,
    expected_ack_key,
)
from seqrun.powercube.protocol import MotionMode, ParamId, ShortState  # noqa: E402

BITRATE = 1_000_000
GOAL = 5.0

try:
    from seqrun.powercube.can_timing import frame_bit_length

    TIMING_SOURCE = "seqrun.powercube.can_timing (exact, stuffing + intermission)"
except ImportError:  # pragma: no cover - the simulator engineer's module is missing
    TIMING_SOURCE = "estimate: 47 + 8*dlc bits + ~15% stuffing + 3 intermission"

    def frame_bit_length(can_id: int, data: bytes = b"", **_: object) -> int:
        return round((47 + 8 * len(data)) * 1.15) + 3


MODULES = range(1, 8)

WORKLOADS = {
    "read_arm (7x 0x62)": (
        [GetParam(m, ParamId.FPOS_STATE_DIO) for m in MODULES],
        [GetParamAck(m, ParamId.FPOS_STATE_DIO,
                     PosStateDio(0.1 * m, ShortState.RAMP_END, 0)) for m in MODULES],
    ),
    "move_ramp (vel+acc+FRAMP)": (
        [SetParam(2, ParamId.TARGET_VEL, 0.77), SetParam(2, ParamId.TARGET_ACC, 0.8),
         SetMotion(2, MotionMode.FRAMP, 1.0)],
        [SetParamAck(2, ParamId.TARGET_VEL), SetParamAck(2, ParamId.TARGET_ACC),
         MotionAck(2, MotionMode.FRAMP)],
    ),
    "step cycle (7x FSTEP_ACK)": (
        [SetMotion(m, MotionMode.FSTEP_ACK, 0.1 * m, 60) for m in MODULES],
        [MotionExtAck(m, MotionMode.FSTEP_ACK, 0.1 * m, ShortState.MOTION, 0)
         for m in MODULES],
    ),
}


def best_rate(func, frames_per_call: int, min_time: float = 0.1, repeat: int = 5) -> float:
    """Frames per second of ``func`` (best of ``repeat`` runs of >= ``min_time`` each)."""
    calls = 1
    while True:
        t0 = time.perf_counter()
        for _ in range(calls):
            func()
        elapsed = time.perf_counter() - t0
        if elapsed >= min_time / 4:
            break
        calls *= 2
    calls = max(1, int(calls * min_time / max(elapsed, 1e-9)))
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(calls):
            func()
        best = min(best, time.perf_counter() - t0)
    return calls * frames_per_call / best


def measure(requests, acks):
    request_frames = [encode(r) for r in requests]
    ack_frames = [encode(a) for a in acks]
    frames = request_frames + ack_frames
    bits = [frame_bit_length(can_id, data) for can_id, data in frames]
    bus_rate = BITRATE / (sum(bits) / len(bits))
    n = len(frames)

    def encode_all():
        for message in requests:
            encode(message)
        for message in acks:
            encode(message)

    def decode_all():
        for can_id, data in request_frames:
            decode_request(can_id, data)
        for can_id, data in ack_frames:
            decode_ack(can_id, data)

    def decode_new():
        # Frames the codec has not seen: its memo of decoded frames emptied first.
        codec._decoded_requests.clear()
        codec._decoded_acks.clear()
        decode_all()

    keys = [expected_ack_key(r) for r in requests]

    def client_path():
        # What PowerCubeClient does per exchange, minus the bus: encode and register each
        # request, then decode each ack and match it against the pending table.
        pending: dict = {}
        for index, request in enumerate(requests):
            encode(request)
            pending.setdefault(keys[index], deque()).append(index)
        for can_id, data in ack_frames:
            queue = pending.get(ack_key(decode_ack(can_id, data)))
            queue.popleft()

    return {
        "bits": sum(bits) / len(bits),
        "bus": bus_rate,
        "encode": best_rate(encode_all, n),
        "decode_new": best_rate(decode_new, n),
        "decode": best_rate(decode_all, n),
        "client": best_rate(client_path, n),
    }


def full_client_rate() -> tuple[float, float]:
    """Frames/s of ``PowerCubeClient.read_arm`` over an instantly answering bus (every
    cost of the client: can.Message objects, listeners off, flush, matching)."""
    import can

    from seqrun.clock import VirtualClock
    from seqrun.powercube.client import PowerCubeClient

    requests, acks = WORKLOADS["read_arm (7x 0x62)"]
    replies = {encode(r)[0]: encode(a) for r, a in zip(requests, acks)}

    class LoopbackBus(can.BusABC):
        def __init__(self) -> None:
            self.queue: deque = deque()
            super().__init__(channel="bench")

        def send(self, msg, timeout=None):
            can_id, data = replies[msg.arbitration_id]
            self.queue.append(can.Message(arbitration_id=can_id, data=data,
                                          is_extended_id=False))

        def recv(self, timeout=None):
            return self.queue.popleft() if self.queue else None

        def _recv_internal(self, timeout):
            return self.recv(timeout), True

    bus = LoopbackBus()
    client = PowerCubeClient(bus, VirtualClock())
    modules = list(MODULES)
    bits = [frame_bit_length(*encode(m)) for m in (*requests, *acks)]
    try:
        rate = best_rate(lambda: client.read_arm(modules), 2 * len(modules))
    finally:
        client.close()
        bus.shutdown()
    return rate, BITRATE / (sum(bits) / len(bits))


def main() -> int:
    print(f"PowerCube codec throughput, one core, Python {sys.version.split()[0]}")
    print(f"bus: {BITRATE / 1e6:g} Mbit/s, frame length from {TIMING_SOURCE}\n")
    header = (f"{'workload':<28}{'bits/frame':>11}{'bus fr/s':>10}{'encode fr/s':>13}"
              f"{'decode new':>13}{'decode seen':>13}{'client fr/s':>13}{'client/bus':>12}")
    print(header)
    print("-" * len(header))
    worst = float("inf")
    for name, (requests, acks) in WORKLOADS.items():
        r = measure(requests, acks)
        ratio = r["client"] / r["bus"]
        worst = min(worst, ratio, r["encode"] / r["bus"], r["decode_new"] / r["bus"])
        print(f"{name:<28}{r['bits']:>11.1f}{r['bus']:>10,.0f}{r['encode']:>13,.0f}"
              f"{r['decode_new']:>13,.0f}{r['decode']:>13,.0f}{r['client']:>13,.0f}"
              f"{ratio:>11.1f}x")
    rate, bus = full_client_rate()
    print(f"{'PowerCubeClient.read_arm':<28}{'':>11}{bus:>10,.0f}{'':>13}{'':>13}{'':>13}"
          f"{rate:>13,.0f}"
          f"{rate / bus:>11.1f}x   (whole client, loopback bus)")
    worst = min(worst, rate / bus)
    verdict = "OK" if worst >= GOAL else "BELOW GOAL"
    print(f"\nslowest path = {worst:.1f}x the bus frame rate (goal >= {GOAL:g}x): {verdict}")
    return 0 if worst >= GOAL else 1


if __name__ == "__main__":
    raise SystemExit(main())
