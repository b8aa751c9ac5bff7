"""The guard work of ``seqrun validate FILE``: forward kinematics, link geometry and workspace
guards, exactly as the static check and the dry run call them, replayed in one process.

One ``seqrun validate`` (static check, then the dry run with its preflight) is run in process
while the calls are recorded: every ``Checker.check_path_guards`` (guards and link volumes
along a planned trajectory; the static check and the preflight each make one per move),
every ``Executor.check_guards`` (one per control cycle of the dry run, on the measured
joints), and every ``Chain.from_arm`` / ``Geometry(arm)`` construction. Then each part is
replayed ``--repeat`` times on the recorded arguments and its time per validate is printed.
The results of the recorded calls (clearances, proximities, lowest heights and distances,
as exact float reprs) are hashed: ``--compare DIR`` runs the same in another checkout and
says whether both computed bit-identical results.

``--instructions`` counts the instructions of each part with valgrind's callgrind (the
process with 20 replays minus the one with none, per replay; the garbage collector is off
while replaying): a figure a loaded host does not change.

Run: ``.venv/bin/python bench/bench_guards.py [--sequence FILE] [--repeat 20]
[--instructions] [--compare DIR]``
"""

from __future__ import annotations

import argparse
import gc
import hashlib
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PARTS = ("path", "cycle", "setup")
DESCRIPTION = {
    "path": "Checker.check_path_guards (planned trajectories, static + preflight)",
    "cycle": "Executor.check_guards (every dry-run cycle)",
    "setup": "Chain.from_arm + Geometry(arm) constructions",
}


def record(sequence: Path) -> tuple[dict, str]:
    """Run the static check and the dry run of ``sequence`` once, recording the calls of
    each part; returns them and a digest of what the recorded calls computed."""
    from seqrun import executor
    from seqrun.arm import kinematics
    from seqrun.sequence import validation
    from seqrun.sequence.checks import static_check
    from seqrun.service.dryrun import dry_run
    from seqrun.arm.geometry import Geometry

    calls: dict[str, list] = {part: [] for part in PARTS}
    path_guards = validation.Checker.check_path_guards
    check_guards = executor.Executor.check_guards
    from_arm = kinematics.Chain.from_arm.__func__
    geometry_init = Geometry.__init__

    def recording_path(self, step, times, path_rad, *, what):
        calls["path"].append((self, step, times.copy(), path_rad.copy(), what))
        return path_guards(self, step, times, path_rad, what=what)

    def recording_cycle(self, m):
        calls["cycle"].append((self, m))
        return check_guards(self, m)

    def recording_from_arm(cls, arm):
        calls["setup"].append(("chain", arm))
        return from_arm(cls, arm)

    def recording_geometry(self, arm):
        calls["setup"].append(("geometry", arm))
        return geometry_init(self, arm)

    validation.Checker.check_path_guards = recording_path
    executor.Executor.check_guards = recording_cycle
    kinematics.Chain.from_arm = classmethod(recording_from_arm)
    Geometry.__init__ = recording_geometry
    try:
        check = static_check(sequence)
        if check.errors:
            raise SystemExit(f"{sequence}: invalid: {check.errors[0]}")
        run = dry_run(check.loaded, check.arm, check.start_deg)
    finally:
        validation.Checker.check_path_guards = path_guards
        executor.Executor.check_guards = check_guards
        kinematics.Chain.from_arm = classmethod(from_arm)
        Geometry.__init__ = geometry_init
    checkers = {id(c[0]): c[0] for c in calls["path"]}
    executors = {id(c[0]): c[0] for c in calls["cycle"]}
    results = {
        "clearances": [{k: repr(getattr(v, k)) for k in vars(v)} for c in checkers.values()
                       for v in c.clearances.values()],
        "proximities": [{k: repr(getattr(v, k)) for k in vars(v)} for c in checkers.values()
                        for v in c.proximities.values()],
        "min_heights_mm": [{k: repr(v) for k, v in e.min_heights_mm.items()}
                           for e in executors.values()],
        "min_distances_mm": [{k: repr(v) for k, v in e.checks.min_distances_mm.items()}
                             for e in executors.values()],
        "errors": [str(e) for c in checkers.values() for e in c.errors],
        "dry_run": [run.passed, repr(run.simulated_s)],
    }
    digest = hashlib.sha256(json.dumps(results, sort_keys=True).encode()).hexdigest()[:16]
    return calls, digest


def replay(part: str, calls: list) -> None:
    if part == "path":
        for checker, step, times, path_rad, what in calls:
            checker.check_path_guards(step, times, path_rad, what=what)
    elif part == "cycle":
        for ex, m in calls:
            ex.check_guards(m)
    else:
        from seqrun.arm.geometry import Geometry
        from seqrun.arm.kinematics import Chain

        for kind, arm in calls:
            Chain.from_arm(arm) if kind == "chain" else Geometry(arm)


def worker(sequence: Path, parts: list[str], repeat: int) -> dict:
    """In this process: record, then replay each part ``repeat`` times (time per replay)."""
    calls, digest = record(sequence)
    out = {"digest": digest, "calls": {p: len(calls[p]) for p in PARTS}, "us": {}}
    gc.collect()
    gc.disable()  # a collection would land in whichever part runs then (noise of millions)
    for part in parts:
        best = float("inf")
        for _ in range(repeat):
            t0 = time.perf_counter()
            replay(part, calls[part])
            best = min(best, time.perf_counter() - t0)
        out["us"][part] = round(best * 1e6, 1) if repeat else None
    return out


def run_worker(tree: Path, sequence: Path, parts: list[str], repeat: int,
               callgrind: bool = False) -> tuple[dict, int | None]:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPATH"] = str(tree)
    env.setdefault("OPENBLAS_NUM_THREADS", "1")  # as the seqrun program sets it
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", "--sequence",
           str(sequence), "--repeat", str(repeat), "--parts", ",".join(parts)]
    if callgrind:
        cmd = ["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null", *cmd]
    proc = subprocess.run(cmd, cwd=tree, env=env, capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"worker in {tree} failed:\n{proc.stderr[-3000:]}")
    count = re.search(r"Collected : (\d+)", proc.stderr)
    return json.loads(proc.stdout.splitlines()[-1]), int(count.group(1)) if count else None


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sequence", type=Path, default=Path("sequences/opsafe.yaml"))
    parser.add_argument("--repeat", type=int, default=20)
    parser.add_argument("--parts", default=",".join(PARTS))
    parser.add_argument("--instructions", action="store_true",
                        help="instructions per part (valgrind's callgrind; ~1 min)")
    parser.add_argument("--compare", type=Path, metavar="DIR",
                        help="another seqrun checkout, measured the same way")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    parts = args.parts.split(",")
    if args.worker:
        print(json.dumps(worker(args.sequence, parts, args.repeat)))
        return 0
    trees = {"this": ROOT}
    if args.compare is not None:
        trees["compare"] = args.compare.resolve()
    sequence = (ROOT / args.sequence).resolve()
    results = {label: run_worker(tree, sequence, parts, args.repeat)[0]
               for label, tree in trees.items()}
    first = next(iter(results.values()))
    print(f"{args.sequence}: calls per validate: "
          + ", ".join(f"{p} {n}" for p, n in first["calls"].items()))
    print(f"\n{'time per validate, best of ' + str(args.repeat) + ' (µs)':56s}"
          + "".join(f" {label:>10s}" for label in trees))
    for part in parts:
        print(f"{DESCRIPTION[part]:56s}" + "".join(f" {r['us'][part]:10.1f}"
                                                   for r in results.values()))
    if args.instructions:
        n = 20
        print(f"\n{'instructions per validate (thousands)':56s}"
              + "".join(f" {label:>10s}" for label in trees))
        for part in parts:
            line = f"{DESCRIPTION[part]:56s}"
            for tree in trees.values():
                _, base = run_worker(tree, sequence, [part], 0, callgrind=True)
                _, more = run_worker(tree, sequence, [part], n, callgrind=True)
                line += f" {((more or 0) - (base or 0)) / n / 1e3:10.0f}"
            print(line, flush=True)
    digests = {label: r["digest"] for label, r in results.items()}
    print("\nresults digest: " + ", ".join(f"{k} {v}" for k, v in digests.items()))
    if len(set(digests.values())) > 1:
        print("results DIFFER between the trees (clearances, proximities, heights, distances)")
    elif len(digests) > 1:
        print("results bit-identical in both trees")
    return 0


if __name__ == "__main__":
    sys.exit(main())
