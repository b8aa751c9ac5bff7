"""Start-up of the short commands against issue 25's bar, measured side by side.

The bar: ``seqrun --help`` under 0.3 s, and a whole ``seqrun validate
sequences/opsafe.yaml`` process (static check and dry run) within 1.5x of the floor any
such process pays: ``python -c "import numpy, pydantic"`` (the interpreter and the two
libraries it cannot do without) plus the dry run itself, timed inside a process that has
already run it once (what ``seqrun.service.dryrun.dry_run`` costs when nothing is left to
import). The ratio is

    median(validate process) / (median(import numpy, pydantic) + median(in-process dry run))

One invocation measures all of it: each round runs ``--help``, the import floor, the
in-process dry run and ``validate`` once each, one after the other, ``--repeat`` rounds,
so that the load of a shared host falls alike on the parts of the ratio. Every process
runs with ``OPENBLAS_NUM_THREADS=1`` and ``PYDANTIC_DISABLE_PLUGINS=__all__``, which the
``seqrun`` program sets for itself, so the floor gets them too.

Bytecode: the processes run with Python's normal ``.pyc`` cache, as an installed seqrun
does (pip compiles it at install); ``PYTHONDONTWRITEBYTECODE`` is dropped from their
environment and everything runs once untimed first, so the cache is written.

``--compare DIR``: a second seqrun checkout (``git worktree add /tmp/before main``)
measured in the same rounds, alternating with this one. ``--instructions``: also the
instructions each seqrun command executes (valgrind's callgrind): a count that a loaded
host does not change, for before/after comparisons.

Run: ``.venv/bin/python bench/bench_startup.py [--repeat 11] [--compare DIR]
[--instructions]``
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from seqrun_runs import RESULTS, ROOT, machine, write_json  # noqa: E402

HELP = "seqrun --help"
FLOOR = "python -c 'import numpy, pydantic'"
DRY_RUN = "dry run in process (warm)"
VALIDATE = "seqrun validate opsafe"
#: The dry run of validate, in a process that has run it once: prints its wall seconds.
DRY_RUN_PROBE = """\
import time
from seqrun.arm.description import load_arm
from seqrun.arm.poses import park_deg
from seqrun.sequence.loader import load_sequence
from seqrun.service.dryrun import dry_run
loaded = load_sequence("sequences/opsafe.yaml")
arm = load_arm(loaded.arm_path)
start = park_deg(loaded.pose_path or loaded.poses_dir)
dry_run(loaded, arm, start)
t0 = time.perf_counter()
run = dry_run(loaded, arm, start)
wall = time.perf_counter() - t0
assert run.passed, run.result.message
print(wall)
"""
PROCESSES = {
    HELP: ["-m", "seqrun", "--help"],
    FLOOR: ["-c", "import numpy, pydantic"],
    DRY_RUN: ["-c", DRY_RUN_PROBE],
    VALIDATE: ["-m", "seqrun", "validate", "sequences/opsafe.yaml"],
}
HELP_GOAL_S = 0.3
RATIO_GOAL = 1.5


def environment(tree: Path) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPATH"] = str(tree)
    env.setdefault("OPENBLAS_NUM_THREADS", "1")
    env.setdefault("PYDANTIC_DISABLE_PLUGINS", "__all__")
    return env


def run_once(tree: Path, args: list[str]) -> tuple[float, float, str]:
    """(wall s, CPU s, stdout) of one ``python ARGS`` in ``tree``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, *args], cwd=tree, env=environment(tree),
                          capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(args)[:60]} in {tree}: exit {proc.returncode}\n"
                         f"{proc.stderr}")
    return wall, after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime, proc.stdout


def instructions(tree: Path, args: list[str]) -> int | None:
    """Instructions executed by ``python ARGS`` in ``tree`` (callgrind's total)."""
    proc = subprocess.run(["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null",
                           sys.executable, *args], cwd=tree, env=environment(tree),
                          capture_output=True, text=True)
    match = re.search(r"Collected : (\d+)", proc.stderr)
    return int(match.group(1)) if match else None


def summary(times: list[float], cpu: list[float]) -> dict:
    return {"min_s": round(min(times), 4), "median_s": round(statistics.median(times), 4),
            "cpu_median_s": round(statistics.median(cpu), 4),
            "runs_s": [round(v, 4) for v in times]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeat", type=int, default=11, help="rounds (default 11)")
    parser.add_argument("--compare", type=Path, metavar="DIR",
                        help="another seqrun checkout, measured alternately with this one")
    parser.add_argument("--instructions", action="store_true",
                        help="instructions per seqrun command (needs valgrind)")
    parser.add_argument("--out", type=Path, default=RESULTS / "startup.json")
    opts = parser.parse_args()
    info = machine()
    trees = {"this": ROOT}
    if opts.compare is not None:
        trees["compare"] = opts.compare.resolve()
    for tree in trees.values():  # untimed: writes the bytecode cache
        for args in PROCESSES.values():
            run_once(tree, args)
    times = {t: {name: [] for name in PROCESSES} for t in trees}
    cpu = {t: {name: [] for name in PROCESSES} for t in trees}
    for _ in range(opts.repeat):
        for name, args in PROCESSES.items():
            for label, tree in trees.items():
                wall, used, out = run_once(tree, args)
                # the probe's figure is the dry run it timed, not its whole process
                times[label][name].append(float(out.split()[-1]) if name == DRY_RUN else wall)
                cpu[label][name].append(used)
    result: dict = {"machine": info, "repeat": opts.repeat, "bytecode_cache": True,
                    "trees": {k: str(v) for k, v in trees.items()},
                    "goals": {"help_s": HELP_GOAL_S, "validate_ratio": RATIO_GOAL}}
    print(f"{'process':34s}" + "".join(
        f" {label + ' min s':>13s} {label + ' med s':>13s} {label + ' CPU s':>13s}"
        for label in trees))
    rows: dict[str, dict] = {label: {} for label in trees}
    for name in PROCESSES:
        line = f"{name:34s}"
        for label in trees:
            rows[label][name] = row = summary(times[label][name], cpu[label][name])
            line += f" {row['min_s']:13.3f} {row['median_s']:13.3f} {row['cpu_median_s']:13.3f}"
        print(line)
    print("(the dry run's CPU column is its whole probe process)")
    result["processes"] = rows["this"]
    if "compare" in rows:
        result["compare_processes"] = rows["compare"]
    print()
    for label in trees:
        row = rows[label]
        floor = row[FLOOR]["median_s"] + row[DRY_RUN]["median_s"]
        ratio = row[VALIDATE]["median_s"] / floor
        per_round = [v / (f + d) for v, f, d in zip(times[label][VALIDATE], times[label][FLOOR],
                                                    times[label][DRY_RUN])]
        help_s = row[HELP]["median_s"]
        result.setdefault("bar", {})[label] = {
            "help_median_s": help_s, "help_met": help_s < HELP_GOAL_S,
            "floor_s": round(floor, 4), "validate_median_s": row[VALIDATE]["median_s"],
            "ratio": round(ratio, 3), "ratio_per_round": [round(r, 3) for r in per_round],
            "ratio_met": ratio <= RATIO_GOAL}
        print(f"{label}: --help {help_s:.3f} s (goal < {HELP_GOAL_S} s: "
              f"{'met' if help_s < HELP_GOAL_S else 'NOT met'}); validate {ratio:.2f}x of "
              f"import numpy, pydantic + dry run ({row[VALIDATE]['median_s']:.3f} s / "
              f"{floor:.3f} s; per round {min(per_round):.2f}-{max(per_round):.2f}x; goal <= "
              f"{RATIO_GOAL}x: {'met' if ratio <= RATIO_GOAL else 'NOT met'})")
    if opts.instructions:
        if shutil.which("valgrind") is None:
            raise SystemExit("--instructions needs valgrind")
        print(f"\n{'instructions (millions)':34s}" + "".join(f" {label:>13s}" for label in trees))
        for name in (HELP, FLOOR, VALIDATE):
            counts = {label: instructions(tree, PROCESSES[name]) for label, tree in trees.items()}
            result.setdefault("instructions", {})[name] = counts
            print(f"{name:34s}" + "".join(f" {(c or 0) / 1e6:13.0f}" for c in counts.values()))
    result["loadavg_at_end"] = [round(x, 2) for x in os.getloadavg()]
    write_json(opts.out, result)
    print(f"written {opts.out}")


if __name__ == "__main__":
    main()
