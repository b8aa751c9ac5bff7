"""The fast test tier as the README runs it: ``pytest -n 2 -m "not slow"``, timed whole.

Goal: under 2 minutes of wall time on 2 idle cores. Each run is a fresh pytest process (its
own temporary folder); the table gives the wall time and the CPU time of pytest and
everything it started (user + system, from ``getrusage(RUSAGE_CHILDREN)``): on a loaded
host the wall time grows, the CPU time far less, so compare CPU seconds when the host is
not idle (the load average before each run is recorded).

``--compare DIR``: a second checkout (e.g. ``git worktree add /tmp/before main``) run in
the same session, alternating run by run with this one, for before/after figures under
the same load. Both use this interpreter; ``PYTHONPATH`` points at each tree in turn.

Run: ``.venv/bin/python bench/bench_fast_tier.py [--repeat 3] [--compare DIR]``
(results: ``bench/results/fast_tier.json``; ``-- tests/test_codec.py`` runs a part of the
tier instead, to check the script, and writes no results)
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from seqrun_runs import RESULTS, ROOT, machine, write_json  # noqa: E402

GOAL_S = 120.0
SUMMARY = re.compile(r"(\d+) (passed|failed|errors?|skipped)")


def run_tier(tree: Path, workers: int, extra: list[str]) -> dict:
    """One ``pytest -n WORKERS -m "not slow"`` in ``tree``: wall, CPU, load, outcome."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    load = os.getloadavg()[0]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="fast-tier-") as tmp:
        proc = subprocess.run([sys.executable, "-m", "pytest", "-n", str(workers),
                               "-m", "not slow", "-p", "no:cacheprovider",
                               "--basetemp", str(Path(tmp) / "t"), *extra],
                              cwd=tree, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    tail = proc.stdout.strip().splitlines()[-1] if proc.stdout.strip() else ""
    counts = {kind.rstrip("s"): int(n) for n, kind in SUMMARY.findall(tail)}
    failed = [line for line in proc.stdout.splitlines() if line.startswith(("FAILED", "ERROR"))]
    return {"wall_s": round(wall, 1), "cpu_s": round(cpu, 1), "load_before": round(load, 2),
            "exit_code": proc.returncode, "counts": counts, "summary": tail, "failed": failed}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--compare", type=Path, help="a second checkout, run alternately")
    parser.add_argument("pytest_args", nargs="*",
                        help="more pytest arguments (after --), e.g. test files for a check")
    args = parser.parse_args()
    trees = {"this": ROOT} | ({"compare": args.compare.resolve()} if args.compare else {})
    runs: dict[str, list[dict]] = {name: [] for name in trees}
    info = machine()
    for i in range(args.repeat):
        for name, tree in trees.items():
            run = run_tier(tree, args.workers, args.pytest_args)
            runs[name].append(run)
            print(f"[{i + 1}/{args.repeat}] {name:8s} wall {run['wall_s']:6.1f} s  "
                  f"cpu {run['cpu_s']:6.1f} s  load before {run['load_before']:.2f}  "
                  f"{run['summary']}", flush=True)
            for line in run["failed"]:
                print(f"    {line}", flush=True)
    summary = {}
    for name, rs in runs.items():
        summary[name] = {"tree": str(trees[name]),
                         "wall_s_median": round(statistics.median(r["wall_s"] for r in rs), 1),
                         "cpu_s_median": round(statistics.median(r["cpu_s"] for r in rs), 1),
                         "all_passed": all(r["exit_code"] == 0 for r in rs), "runs": rs}
        s = summary[name]
        print(f"{name:8s} median wall {s['wall_s_median']:.1f} s (goal < {GOAL_S:.0f} s), "
              f"median cpu {s['cpu_s_median']:.1f} s, all passed: {s['all_passed']}")
    if "compare" in summary:
        ratio = summary["this"]["cpu_s_median"] / summary["compare"]["cpu_s_median"]
        print(f"cpu this / compare: {ratio:.2f}")
    if args.pytest_args:  # a part of the tier: not the figure the README quotes
        return
    write_json(RESULTS / "fast_tier.json",
               {"machine": info, "workers": args.workers, "goal_wall_s": GOAL_S, **summary})


if __name__ == "__main__":
    main()
