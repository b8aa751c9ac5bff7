"""Dry-run speed: simulated seconds of sequences/opsafe.yaml per wall second.

Runs the real executor through the real client and codec against the simulated arm on a
VirtualClock (what ``seqrun validate`` does), ``--runs`` times after one warm-up run, and
prints the median wall time and speedup = simulated duration / wall time. The loop runs
at the arm file's ``control.cycle_hz`` (the dry run's rate since issue 29); ``--cycle-hz
10`` gives the rate the dry run had before, ``--compare-hz 10`` both, alternating run by
run (side by side under the same load).

``--cold`` empties the simulator's frame-length cache, the bit-stuffing tables and the
codec's decoded frames before every run, as a one-shot ``seqrun validate`` process starts
(the warm runs otherwise find them filled by the warm-up run, since the runs are
deterministic).

Run: ``.venv/bin/python bench/perf_dryrun.py [--runs 15] [--cold] [--profile] [--sequence FILE]
[--cycle-hz HZ] [--compare-hz HZ]``
"""

from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from seqrun.arm.description import load_arm
from seqrun.clock import VirtualClock
from seqrun.executor import Executor
from seqrun.sequence.checks import check_from_arm
from seqrun.powercube.client import PowerCubeClient
from seqrun.sequence.loader import load_sequence
from seqrun.powercube import can_timing
from seqrun.powercube import codec
from seqrun.sim import network
from seqrun.sim.bus import SimBus


def one(loaded, arm, i: int, cold: bool = False, cycle_hz: float | None = None):
    if cold:  # every in-process table a fresh process starts without
        network._bit_length.cache_clear()
        can_timing._after_header.cache_clear()
        can_timing._stuff_table[:] = [0] * len(can_timing._stuff_table)
        can_timing._stuff_partials.clear()
        codec._decoded_requests.clear()
        codec._decoded_acks.clear()
    clock = VirtualClock()
    bus = SimBus(channel=f"perf{i}", clock=clock)
    client = PowerCubeClient(bus, clock)
    ex = Executor(client, arm, clock, sequence_check=check_from_arm,
                  poses_dir=loaded.poses_dir, dry_run=True,
                  cycle_hz=cycle_hz or arm.control.cycle_hz)
    w, c = time.perf_counter(), time.thread_time()
    res = ex.run(loaded)
    w, c = time.perf_counter() - w, time.thread_time() - c
    bus.shutdown()
    one.cpu = c  # type: ignore[attr-defined]
    return res, w


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=15)
    parser.add_argument("--profile", action="store_true", help="cProfile top 25 by tottime")
    parser.add_argument("--cold", action="store_true",
                        help="empty the frame-length cache before each run")
    parser.add_argument("--sequence", default="sequences/opsafe.yaml")
    parser.add_argument("--cycle-hz", type=float, default=None,
                        help="loop rate (default: the arm file's control.cycle_hz)")
    parser.add_argument("--compare-hz", type=float, default=None,
                        help="also this rate, alternating run by run with --cycle-hz's")
    args = parser.parse_args()

    loaded = load_sequence(args.sequence)
    arm = load_arm(loaded.arm_path)
    rates = [args.cycle_hz or arm.control.cycle_hz]
    if args.compare_hz:
        rates.append(args.compare_hz)
    for hz in rates:
        one(loaded, arm, 0, cycle_hz=hz)  # warm-up (imports, caches)
    if args.profile:
        profiler = cProfile.Profile()
        profiler.enable()
        res, w = one(loaded, arm, 1, args.cold, rates[0])
        profiler.disable()
        pstats.Stats(profiler).sort_stats("tottime").print_stats(25)
        print(f"profiled run at {rates[0]:g} Hz: {res.duration_s:.3f} s simulated in "
              f"{w:.3f} s wall")
        return 0
    walls: dict[float, list[float]] = {hz: [] for hz in rates}
    cpus: dict[float, list[float]] = {hz: [] for hz in rates}
    simulated = {}
    for i in range(args.runs):
        for hz in rates:
            res, w = one(loaded, arm, i + 1, args.cold, hz)
            walls[hz].append(w)
            cpus[hz].append(one.cpu)  # type: ignore[attr-defined]
            simulated[hz] = res.duration_s
    print(f"{args.sequence}, {args.runs} {'cold-cache' if args.cold else 'warm'} runs per "
          f"rate, load average {[round(x, 2) for x in os.getloadavg()]}:")
    for hz in rates:
        wall, cpu = statistics.median(walls[hz]), statistics.median(cpus[hz])
        print(f"  {hz:5g} Hz: {simulated[hz]:.3f} s simulated, median wall "
              f"{wall * 1e3:.1f} ms (min {min(walls[hz]) * 1e3:.1f}, max "
              f"{max(walls[hz]) * 1e3:.1f}): {simulated[hz] / wall:.1f}x real time; on "
              f"thread CPU time {simulated[hz] / cpu:.1f}x (median {cpu * 1e3:.1f} ms)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
