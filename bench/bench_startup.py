"""Short commands as whole processes: what the operator waits for after pressing Enter.

Each command runs as ``python -m seqrun …`` (a fresh interpreter, as the ``seqrun`` script
does), ``--repeat`` times, interleaved; the table gives min and median wall time and the
median CPU time (user + system: on a loaded host it moves far less than the wall time).
For ``seqrun validate sequences/opsafe.yaml`` (dry run included) it also gives the
simulated time the dry run reports and the ratio simulated / whole-process wall time
against the goal (>= 50x). ``python -c pass`` and ``python -c "import typer"`` are the
floor any command pays. Goals: ``seqrun --help`` under 0.3 s; validate >= 50x.

Bytecode: the commands run with Python's normal ``.pyc`` cache, as an installed seqrun
does (pip compiles it at install); ``PYTHONDONTWRITEBYTECODE`` is dropped from their
environment and every command runs once untimed first, so the cache is written.
Otherwise each process compiles seqrun's modules again (~0.1 s) and the numbers measure
the compiler.

``--compare DIR``: a second seqrun checkout (e.g. ``git worktree add /tmp/before main``)
measured in the same run, alternating command by command with this one, for before/after
figures under the same load. ``--imports N``: also the import time of ``validate opsafe``
by package (``python -X importtime``, the smallest of N runs per module).
``--instructions``: also the instructions each seqrun command executes (valgrind's
callgrind, ~50x slower): a count that a loaded host does not change, for before/after.

Run: ``.venv/bin/python bench/bench_startup.py [--repeat 7] [--compare DIR] [--imports 5]
[--instructions]``
"""

from __future__ import annotations

import argparse
import collections
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

COMMANDS = {
    "python -c pass": ["-c", "pass"],
    "python -c 'import typer'": ["-c", "import typer"],
    "seqrun --help": ["-m", "seqrun", "--help"],
    "seqrun fk --pose totem": ["-m", "seqrun", "fk", "--pose", "totem"],
    "seqrun validate --static opsafe": ["-m", "seqrun", "validate", "--static",
                                        "sequences/opsafe.yaml"],
    "seqrun validate opsafe": ["-m", "seqrun", "validate", "sequences/opsafe.yaml"],
}
VALIDATE = "seqrun validate opsafe"
GOAL_RATIO = 50
SIMULATED = re.compile(r"([0-9.]+) s simulated in")


def environment(tree: Path) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPATH"] = str(tree)
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
        raise SystemExit(f"{' '.join(args)} in {tree}: exit {proc.returncode}\n{proc.stderr}")
    return wall, after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime, proc.stdout


def import_breakdown(tree: Path, runs: int) -> dict[str, float]:
    """Milliseconds of import time (self, smallest of ``runs``) by top-level package;
    seqrun by module, the standard library as one entry."""
    best: dict[str, int] = {}
    for _ in range(runs):
        proc = subprocess.run([sys.executable, "-X", "importtime", *COMMANDS[VALIDATE][0:]],
                              cwd=tree, env=environment(tree), capture_output=True, text=True)
        for line in proc.stderr.splitlines():
            if not line.startswith("import time:") or "self [us]" in line:
                continue
            self_us, _, name = (part.strip() for part in line[12:].split("|"))
            best[name] = min(best.get(name, 1 << 62), int(self_us))
    groups: collections.Counter[str] = collections.Counter()
    for name, us in best.items():
        top = name.split(".")[0]
        if top == "seqrun":
            top = ".".join(name.split(".")[:2])
        elif top.lstrip("_") in sys.stdlib_module_names or top in sys.stdlib_module_names:
            top = "(standard library)"
        groups[top] += us
    return {name: round(us / 1000, 1) for name, us in groups.most_common()}


def instructions(tree: Path, args: list[str]) -> int | None:
    """Instructions executed by ``python ARGS`` in ``tree`` (callgrind's total)."""
    proc = subprocess.run(["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null",
                           sys.executable, *args], cwd=tree, env=environment(tree),
                          capture_output=True, text=True)
    match = re.search(r"Collected : (\d+)", proc.stderr)
    return int(match.group(1)) if match else None


def summary(times: list[float], cpu: list[float]) -> dict:
    return {"min_s": round(min(times), 3), "median_s": round(statistics.median(times), 3),
            "cpu_median_s": round(statistics.median(cpu), 3),
            "runs_s": [round(v, 3) for v in times]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeat", type=int, default=7)
    parser.add_argument("--compare", type=Path, metavar="DIR",
                        help="another seqrun checkout, measured alternately with this one")
    parser.add_argument("--imports", type=int, default=0, metavar="N",
                        help="import-time breakdown of validate opsafe (smallest of N runs)")
    parser.add_argument("--instructions", action="store_true",
                        help="instructions per seqrun command (needs valgrind)")
    parser.add_argument("--out", type=Path, default=RESULTS / "startup.json")
    opts = parser.parse_args()
    info = machine()
    trees = {"this": ROOT}
    if opts.compare is not None:
        trees["compare"] = opts.compare.resolve()
    for tree in trees.values():  # untimed: writes the bytecode cache
        for args in COMMANDS.values():
            run_once(tree, args)
    times = {t: {name: [] for name in COMMANDS} for t in trees}
    cpu = {t: {name: [] for name in COMMANDS} for t in trees}
    simulated: dict[str, list[float]] = {t: [] for t in trees}
    for _ in range(opts.repeat):
        for name, args in COMMANDS.items():
            for label, tree in trees.items():
                wall, used, out = run_once(tree, args)
                times[label][name].append(wall)
                cpu[label][name].append(used)
                match = SIMULATED.search(out)
                if match and name == VALIDATE:
                    simulated[label].append(float(match.group(1)))
    result: dict = {"machine": info, "repeat": opts.repeat, "bytecode_cache": True,
                    "trees": {k: str(v) for k, v in trees.items()}}
    header = f"{'command':34s}" + "".join(
        f" {label + ' min s':>13s} {label + ' med s':>13s} {label + ' CPU s':>13s}"
        for label in trees)
    print(header)
    rows = {label: {} for label in trees}
    for name in COMMANDS:
        line = f"{name:34s}"
        for label in trees:
            rows[label][name] = row = summary(times[label][name], cpu[label][name])
            line += f" {row['min_s']:13.3f} {row['median_s']:13.3f} {row['cpu_median_s']:13.3f}"
        print(line)
    result["commands"] = rows["this"]
    if "compare" in rows:
        result["compare_commands"] = rows["compare"]
    print()
    for label in trees:
        if not simulated[label]:
            continue
        sim = statistics.median(simulated[label])
        wall = rows[label][VALIDATE]["median_s"]
        ratio = sim / wall
        verdict = "met" if ratio >= GOAL_RATIO else f"not met: needs <= {sim / GOAL_RATIO:.3f} s"
        result.setdefault("validate_opsafe", {})[label] = {
            "simulated_s": sim, "process_wall_s": wall, "ratio": round(ratio, 1),
            "goal": GOAL_RATIO, "met": ratio >= GOAL_RATIO}
        print(f"validate opsafe ({label}): {sim:.2f} s simulated, whole process {wall:.3f} s "
              f"(median): {ratio:.0f}x, goal {GOAL_RATIO}x {verdict}")
    if opts.imports:
        for label, tree in trees.items():
            groups = import_breakdown(tree, opts.imports)
            result.setdefault("validate_import_ms", {})[label] = groups
            print(f"\nimport time of validate opsafe ({label}, ms, smallest of {opts.imports}): "
                  f"total {sum(groups.values()):.0f}")
            for name, ms in list(groups.items())[:25]:
                print(f"  {name:32s} {ms:7.1f}")
    if opts.instructions:
        if shutil.which("valgrind") is None:
            raise SystemExit("--instructions needs valgrind")
        print(f"\n{'instructions (millions)':34s}" + "".join(f" {label:>13s}" for label in trees))
        for name, args in COMMANDS.items():
            if not name.startswith("seqrun"):
                continue
            counts = {label: instructions(tree, args) for label, tree in trees.items()}
            result.setdefault("instructions", {})[name] = counts
            print(f"{name:34s}" + "".join(f" {(c or 0) / 1e6:13.0f}" for c in counts.values()))
    result["loadavg_at_end"] = [round(x, 2) for x in os.getloadavg()]
    write_json(opts.out, result)
    print(f"written {opts.out}")


if __name__ == "__main__":
    main()
