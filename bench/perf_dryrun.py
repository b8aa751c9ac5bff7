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

``--compare DIR`` measures this checkout against another (e.g. ``git worktree add
/tmp/dr-main main``) side by side: each round runs ``--runs`` dry runs of each sequence
given (default opsafe and totem) in a fresh process per checkout, the checkouts
alternating, the way ``seqrun validate`` runs them (:func:`seqrun.service.dryrun.dry_run`:
the simulator's python-can-free port); it prints the median thread CPU time and the
speed (simulated s per CPU s and per wall s) of each and their ratio.

Run: ``.venv/bin/python bench/perf_dryrun.py [--runs 15] [--cold] [--profile] [--sequence FILE]
[--cycle-hz HZ] [--compare-hz HZ]``, or ``[--compare DIR] [--rounds 5] [--runs 3]
[--sequence FILE ...]``
"""

from __future__ import annotations

import argparse
import cProfile
import json
import os
import pstats
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

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


#: One process's share of ``--compare``: warm-up, then timed dry runs as validate runs them.
_CHILD = r"""
import json, os, sys, time
sys.path.insert(0, os.getcwd())
from pathlib import Path
from seqrun.sequence.checks import static_check
import seqrun.service.dryrun as dryrun
check = static_check(Path(sys.argv[1]))
dryrun.dry_run(check.loaded, check.arm, check.start_deg)
cpu, wall = [], []
for _ in range(int(sys.argv[2])):
    w, c = time.perf_counter(), time.thread_time()
    run = dryrun.dry_run(check.loaded, check.arm, check.start_deg)
    cpu.append(time.thread_time() - c)
    wall.append(time.perf_counter() - w)
    assert run.passed, run.result.message
print(json.dumps({"cpu": cpu, "wall": wall, "simulated_s": run.simulated_s}))
"""


def compare(other: Path, sequences: list[str], rounds: int, runs: int) -> int:
    trees = {"this": ROOT, "compare": other.resolve()}
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env.setdefault("OPENBLAS_NUM_THREADS", "1")
    figures: dict[tuple[str, str], dict[str, list[float]]] = {}
    simulated: dict[str, float] = {}
    loads = [os.getloadavg()[0]]
    for _ in range(rounds):
        for sequence in sequences:
            for label, tree in trees.items():
                proc = subprocess.run([sys.executable, "-c", _CHILD, sequence, str(runs)],
                                      cwd=tree, env={**env, "PYTHONPATH": str(tree)},
                                      capture_output=True, text=True)
                if proc.returncode != 0:
                    raise SystemExit(f"{tree}: exit {proc.returncode}\n{proc.stderr[-2000:]}")
                got = json.loads(proc.stdout.strip().splitlines()[-1])
                entry = figures.setdefault((sequence, label), {"cpu": [], "wall": []})
                entry["cpu"] += got["cpu"]
                entry["wall"] += got["wall"]
                simulated[sequence] = got["simulated_s"]
        loads.append(os.getloadavg()[0])
    print(f"{rounds} rounds x {runs} dry runs per checkout and sequence, 1-minute load "
          f"{min(loads):.1f}-{max(loads):.1f}:")
    for sequence in sequences:
        cpus = {}
        for label, tree in trees.items():
            entry = figures[sequence, label]
            cpu, wall = statistics.median(entry["cpu"]), statistics.median(entry["wall"])
            cpus[label] = cpu
            print(f"  {sequence} {label:8s} {tree}: median CPU {cpu * 1e3:.1f} ms "
                  f"({simulated[sequence] / cpu:.1f}x real time), wall {wall * 1e3:.1f} ms "
                  f"({simulated[sequence] / wall:.1f}x)")
        print(f"  {sequence}: this / compare CPU time {cpus['this'] / cpus['compare']:.3f}")
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=15)
    parser.add_argument("--profile", action="store_true", help="cProfile top 25 by tottime")
    parser.add_argument("--cold", action="store_true",
                        help="empty the frame-length cache before each run")
    parser.add_argument("--sequence", action="append", default=None,
                        help="sequence file (with --compare: repeatable; default opsafe and "
                        "totem)")
    parser.add_argument("--compare", type=Path, metavar="DIR",
                        help="another checkout, measured side by side (see the docstring)")
    parser.add_argument("--rounds", type=int, default=5, help="with --compare")
    parser.add_argument("--cycle-hz", type=float, default=None,
                        help="loop rate (default: the arm file's control.cycle_hz)")
    parser.add_argument("--compare-hz", type=float, default=None,
                        help="also this rate, alternating run by run with --cycle-hz's")
    args = parser.parse_args()
    if args.compare is not None:
        return compare(args.compare, args.sequence or ["sequences/opsafe.yaml",
                                                       "sequences/totem.yaml"],
                       args.rounds, 3 if args.runs == 15 else args.runs)
    args.sequence = (args.sequence or ["sequences/opsafe.yaml"])[0]

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
