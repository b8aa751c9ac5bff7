"""Full-arm refresh rate through PowerCubeClient on the timed 1 Mbit/s simulator.

One refresh = ``client.read_arm(1..7)``: seven pipelined GetExtended FPosStateDio (0x62)
requests and their seven 8-byte acknowledges, 14 frames. The simulated wire gives every
frame its exact bit length (stuff bits, CRC, intermission: ``seqrun.powercube.can_timing``), so the
bus limit is ``bitrate / sum(bits of the 14 frames)`` refreshes per second. The rest of a
refresh is the modules' processing latency (100 µs, at least once per refresh: the last
ack cannot start before its request arrived) and, in real time, Python.

Measured twice:
- virtual time (``VirtualClock``): the simulated arm alone — what the protocol allows;
- real time (``RealClock``, the default of ``seqrun-sim``): what this machine's Python
  achieves end to end with the simulated bus in the same process.

Goal: at least 85 % of the bus limit.

Run: ``.venv/bin/python bench/bench_refresh.py [--seconds 2] [--moving]``
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from seqrun.powercube.can_timing import frame_bit_length  # noqa: E402
from seqrun.clock import Clock, RealClock, VirtualClock  # noqa: E402
from seqrun.powercube.client import PowerCubeClient  # noqa: E402
from seqrun.powercube.codec import GetParam, GetParamAck, PosStateDio, encode  # noqa: E402
from seqrun.powercube.protocol import ParamId  # noqa: E402
from seqrun.sim.arm import DEFAULT_MODULE_LATENCY  # noqa: E402
from seqrun.sim.bus import SimBus  # noqa: E402

MODULES = range(1, 8)
BITRATE = 1_000_000
GOAL = 0.85


def refresh_bits(client: PowerCubeClient) -> int:
    """Bits on the wire of one refresh, from the frames of the arm's current readings."""
    total = 0
    for reading in client.read_arm(MODULES):
        total += frame_bit_length(*encode(GetParam(reading.module, ParamId.FPOS_STATE_DIO)))
        ack = GetParamAck(reading.module, ParamId.FPOS_STATE_DIO,
                          PosStateDio(reading.position, reading.state, reading.dio))
        total += frame_bit_length(*encode(ack))
    return total


def run(clock: Clock, seconds: float, moving: bool, channel: str) -> dict:
    bus = SimBus(channel, clock=clock, bitrate=BITRATE)
    client = PowerCubeClient(bus, clock, owns_bus=True)
    try:
        client.reset()
        client.home()
        if moving:  # positions change every refresh, so do the stuff bits
            for module in MODULES:
                client.move_velocity(module, 0.01 * module)
        bits = refresh_bits(client)
        network = bus.network
        busy_before, frames_before = network.busy_time, network.frames_transmitted
        count = 0
        wall_start, sim_start = time.perf_counter(), clock.now()
        while clock.now() - sim_start < seconds:
            client.read_arm(MODULES)
            count += 1
        sim_elapsed = clock.now() - sim_start
        wall_elapsed = time.perf_counter() - wall_start
        return {
            "refreshes": count,
            "rate": count / sim_elapsed,
            "limit": BITRATE / bits,
            # The true ceiling of a synchronous refresh: the wire time of its frames plus one
            # module answer latency (the last ack cannot start before its request is in).
            "ceiling": 1.0 / (bits / BITRATE + DEFAULT_MODULE_LATENCY),
            "bits": bits,
            "utilisation": (network.busy_time - busy_before) / sim_elapsed,
            "frames": network.frames_transmitted - frames_before,
            "wall_per_refresh_us": wall_elapsed / count * 1e6,
        }
    finally:
        client.close()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=2.0,
                        help="simulated seconds per run (real time: wall seconds)")
    parser.add_argument("--moving", action="store_true", help="joints move during the run")
    args = parser.parse_args()

    rows = [("virtual time", run(VirtualClock(), args.seconds, args.moving, "bench-virtual")),
            ("real time", run(RealClock(), args.seconds, args.moving, "bench-real"))]
    print(f"full-arm refresh (7 x FPosStateDio, 14 frames) at {BITRATE // 1000} kbit/s, "
          f"{'moving' if args.moving else 'resting'} arm")
    header = (f"{'clock':<13} {'refreshes':>9} {'rate /s':>9} {'bus limit /s':>12} "
              f"{'of limit':>8} {'of ceiling':>10} {'bus busy':>8} {'wall us/refresh':>15}")
    print(header)
    print("-" * len(header))
    ok = True
    for name, r in rows:
        share = r["rate"] / r["limit"]
        ok &= share >= GOAL
        print(f"{name:<13} {r['refreshes']:>9} {r['rate']:>9.1f} {r['limit']:>12.1f} "
              f"{share:>8.1%} {r['rate'] / r['ceiling']:>10.1%} {r['utilisation']:>8.1%} "
              f"{r['wall_per_refresh_us']:>15.0f}")
    print(f"bus limit: {rows[0][1]['bits']} bits per refresh (14 frames incl. stuffing and "
          f"intermission); frames counted on the wire: {rows[0][1]['frames']} "
          f"= 14 x {rows[0][1]['frames'] / rows[0][1]['refreshes']:.2f}")
    ceiling = rows[0][1]["ceiling"]
    print(f"ceiling: {ceiling:.1f} refreshes/s = {ceiling / rows[0][1]['limit']:.1%} of the bus "
          f"limit: a refresh also waits one module answer latency "
          f"({DEFAULT_MODULE_LATENCY * 1e6:.0f} us), which no pipelining hides")
    print(f"goal >= {GOAL:.0%} of the bus limit: {'met' if ok else 'NOT met'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
