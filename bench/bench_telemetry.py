"""Full-arm telemetry refresh: the thesis' way against seqrun's, and the bus limit.

One refresh = the position of every joint the reader uses, on the simulated LWA 3
(``seqrun-sim``, 1 Mbit/s, exact frame lengths), arm resting after Reset and Home:

- thesis, as listed: ``Dugtrio.read()`` (appendix B): GetExtended ActPos of modules 1, 2,
  4-7 (module 3 unused), one ``launcher`` call each, i.e. one request, a 1-second pause,
  then its acknowledge - 6 s per refresh (``bench/thesis_baseline.py``);
- thesis pattern without the waits: the same requests, one at a time, each sent as soon as
  the previous acknowledge is in (for a fair comparison; also for all 7 modules);
- seqrun: ``PowerCubeClient.read_arm(1..7)``: seven GetExtended FPosStateDio (0x62: position,
  state and dio) sent back to back, then the seven acknowledges collected (pipelined);
- bus limit: ``bitrate / sum of the frames' bit lengths`` (``seqrun.powercube.can_timing``: stuff
  bits, CRC, EOF, intermission) of one seqrun refresh; the same bound is given for each
  pattern's own frames. The modules' processing latency is not in it;
- ceiling: the bus limit with one module answer latency (100 us) added per refresh: a
  synchronous refresh cannot hide the last acknowledge's latency, so this (about 93 % of
  the bus limit) is what a perfect host could reach.

Each pattern runs in virtual time (the simulated arm alone: what the protocol allows) and
in real time (this machine's Python with the simulator in the same process).

Run: ``.venv/bin/python bench/bench_telemetry.py [--seconds 2] [--repeat 3]``
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from seqrun_runs import RESULTS, load_shipped, machine, median, write_json  # noqa: E402
from thesis_baseline import READ_MODULES, ThesisSession  # noqa: E402

from seqrun.powercube.can_timing import frame_bit_length  # noqa: E402
from seqrun.clock import RealClock, VirtualClock  # noqa: E402
from seqrun.powercube.client import PowerCubeClient  # noqa: E402
from seqrun.powercube.codec import GetParam, GetParamAck, PosStateDio, encode  # noqa: E402
from seqrun.powercube.protocol import ParamId  # noqa: E402
from seqrun.sim.arm import DEFAULT_MODULE_LATENCY  # noqa: E402
from seqrun.sim.bus import SimBus  # noqa: E402

ALL_MODULES = tuple(range(1, 8))
_channel = iter(range(10**6))


def _prepared(clock):
    """A simulated arm after Reset and Home (as both procedures leave it)."""
    _, arm = load_shipped("opsafe")
    bus = SimBus(f"bench-telemetry-{next(_channel)}", clock=clock, bitrate=arm.can.bitrate)
    client = PowerCubeClient(bus, clock)
    client.reset()
    client.home()
    client.idle(0.01)
    return arm, bus, client


def wire_bits(client: PowerCubeClient, modules, param: ParamId) -> int:
    """Bits on the wire of one refresh reading ``param`` of ``modules`` (requests + acks)."""
    total = 0
    for module in modules:
        value = client.get_param(module, param)
        if param is ParamId.FPOS_STATE_DIO:
            value = PosStateDio(value.position, value.state, value.dio)
        total += frame_bit_length(*encode(GetParam(module, param)))
        total += frame_bit_length(*encode(GetParamAck(module, param, value)))
    return total


def measure(pattern: str, clock, seconds: float, min_refreshes: int = 1) -> dict:
    arm, bus, client = _prepared(clock)
    try:
        if pattern == "seqrun":
            modules, param = ALL_MODULES, ParamId.FPOS_STATE_DIO

            def refresh():
                client.read_arm(ALL_MODULES)
        else:
            modules = READ_MODULES if pattern != "thesis-nowait-7" else ALL_MODULES
            param = ParamId.ACT_POS
            session = ThesisSession(bus, clock, arm,
                                    pause_s=1.0 if pattern == "thesis" else None)

            def refresh():
                for module in modules:
                    reply = session.launcher(GetParam(module, ParamId.ACT_POS))
                    if reply is None:
                        raise RuntimeError(f"module {module}: no acknowledge")
        bits = wire_bits(client, modules, param)
        frames_before = bus.network.frames_transmitted
        count = 0
        c0, w0 = clock.now(), time.perf_counter()
        while count < min_refreshes or clock.now() - c0 < seconds:
            refresh()
            count += 1
        elapsed = clock.now() - c0
        wall = time.perf_counter() - w0
        return {"refreshes": count, "rate": count / elapsed, "modules": len(modules),
                "bits": bits, "wire_limit": bus.bitrate / bits,
                "frames_per_refresh": (bus.network.frames_transmitted - frames_before) / count,
                "wall_us_per_refresh": wall / count * 1e6}
    finally:
        client.close()
        bus.shutdown()


PATTERNS = (
    ("thesis", "thesis Dugtrio.read(): 1 s after each request"),
    ("thesis-nowait", "thesis pattern, no waits (6 modules)"),
    ("thesis-nowait-7", "thesis pattern, no waits, all 7 modules"),
    ("seqrun", "seqrun client.read_arm (7 pipelined)"),
)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=2.0,
                        help="seconds per measurement (the 1-s-wait pattern: 1 refresh)")
    parser.add_argument("--repeat", type=int, default=3, help="repetitions (median reported)")
    args = parser.parse_args()
    info = machine()
    results: dict = {}
    for key, _ in PATTERNS:
        for clock_name in ("virtual", "real"):
            runs = []
            for _ in range(args.repeat if key != "thesis" or clock_name == "virtual" else 1):
                clock = VirtualClock() if clock_name == "virtual" else RealClock()
                seconds = 0.0 if key == "thesis" else args.seconds
                runs.append(measure(key, clock, seconds))
            results[(key, clock_name)] = {
                **{k: runs[0][k] for k in ("modules", "bits", "wire_limit",
                                           "frames_per_refresh")},
                "rate": median([r["rate"] for r in runs]),
                "wall_us_per_refresh": median([r["wall_us_per_refresh"] for r in runs]),
                "rates": [round(r["rate"], 3) for r in runs]}
    seqrun_bits = results[("seqrun", "virtual")]["bits"]
    bitrate = 1_000_000
    limit = bitrate / seqrun_bits
    print(f"full-arm telemetry refresh on the simulated LWA 3 at {bitrate // 1000} kbit/s, "
          f"median of {args.repeat} x {args.seconds:g} s (the 1-s pattern: one refresh "
          f"in real time)")
    header = (f"{'pattern':<48}{'modules':>8}{'virtual /s':>12}{'real /s':>10}"
              f"{'of bus limit':>13}{'wire-only /s':>13}{'vs thesis':>11}")
    print(header)
    print("-" * len(header))
    thesis_rate = results[("thesis", "real")]["rate"]
    for key, label in PATTERNS:
        v, r = results[(key, "virtual")], results[(key, "real")]
        print(f"{label:<48}{v['modules']:>8}{v['rate']:>12.3f}{r['rate']:>10.3f}"
              f"{r['rate'] / limit:>13.1%}{v['wire_limit']:>13.1f}"
              f"{r['rate'] / thesis_rate:>10.0f}x")
    ceiling = 1.0 / (seqrun_bits / bitrate + DEFAULT_MODULE_LATENCY)
    print(f"{'ceiling: bus limit + one module latency':<48}{7:>8}{ceiling:>12.1f}{ceiling:>10.1f}"
          f"{ceiling / limit:>13.1%}{limit:>13.1f}{ceiling / thesis_rate:>10.0f}x")
    print(f"{'bus limit (7 x FPosStateDio, 14 frames)':<48}{7:>8}{limit:>12.1f}{limit:>10.1f}"
          f"{1:>13.1%}{limit:>13.1f}{limit / thesis_rate:>10.0f}x")
    print(f"\nbus limit: {seqrun_bits} bits per seqrun refresh (14 frames incl. stuffing and "
          f"intermission). 'of bus limit' and 'vs thesis' use the real-time rates.")
    print("wire-only: bitrate / bits of that pattern's own frames (no module latency, "
          "no waiting). ActPos reads give the position only; FPosStateDio adds state and dio.")
    rows = {f"{k}/{c}": {kk: (round(vv, 4) if isinstance(vv, float) else vv)
                         for kk, vv in val.items()} for (k, c), val in results.items()}
    write_json(RESULTS / "telemetry.json", {
        "benchmark": "bench_telemetry", "machine": info, "repeat": args.repeat,
        "seconds": args.seconds,
        "command": "python bench/bench_telemetry.py " + " ".join(sys.argv[1:]),
        "bus_limit_per_s": round(limit, 2), "bus_limit_bits": seqrun_bits,
        "ceiling_per_s": round(ceiling, 2),
        "module_latency_s": DEFAULT_MODULE_LATENCY,
        "patterns": dict(PATTERNS), "results": rows})
    print(f"results: {RESULTS / 'telemetry.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
