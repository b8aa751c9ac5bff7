"""Short commands as whole processes: what the operator waits for after pressing Enter.

Each command runs as ``python -m seqrun …`` (a fresh interpreter, as the ``seqrun`` script
does), ``--repeat`` times, interleaved; the table gives min and median wall time. For
``seqrun validate sequences/opsafe.yaml`` (dry run included) it also gives the simulated
time the dry run reports and the ratio simulated / whole-process wall time (goal >= 50x).
``python -c pass`` and ``python -c "import typer"`` are the floor any command pays. The CPU
time (user + system) of each process is given too: on a loaded host it moves far less than
the wall time.
Goals: ``seqrun --help`` under 0.3 s.

Run: ``.venv/bin/python bench/bench_startup.py [--repeat 7]``
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from seqrun_runs import RESULTS, ROOT, machine, write_json  # noqa: E402

COMMANDS = {
    "python -c pass": [sys.executable, "-c", "pass"],
    "python -c 'import typer'": [sys.executable, "-c", "import typer"],
    "seqrun --help": [sys.executable, "-m", "seqrun", "--help"],
    "seqrun fk --pose totem": [sys.executable, "-m", "seqrun", "fk", "--pose", "totem"],
    "seqrun validate --static opsafe": [sys.executable, "-m", "seqrun", "validate", "--static",
                                        "sequences/opsafe.yaml"],
    "seqrun validate opsafe": [sys.executable, "-m", "seqrun", "validate",
                               "sequences/opsafe.yaml"],
}
SIMULATED = re.compile(r"([0-9.]+) s simulated in")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeat", type=int, default=7)
    parser.add_argument("--out", type=Path, default=RESULTS / "startup.json")
    opts = parser.parse_args()
    info = machine()
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    times: dict[str, list[float]] = {name: [] for name in COMMANDS}
    cpu: dict[str, list[float]] = {name: [] for name in COMMANDS}
    simulated: list[float] = []
    for _ in range(opts.repeat):
        for name, argv in COMMANDS.items():
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            t0 = time.perf_counter()
            proc = subprocess.run(argv, cwd=ROOT, env=env, capture_output=True, text=True)
            times[name].append(time.perf_counter() - t0)
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu[name].append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
            if proc.returncode != 0:
                raise SystemExit(f"{name}: exit {proc.returncode}\n{proc.stderr}")
            match = SIMULATED.search(proc.stdout)
            if match and name == "seqrun validate opsafe":
                simulated.append(float(match.group(1)))
    rows = {}
    print(f"{'command':36s} {'min s':>7s} {'median s':>9s} {'CPU median s':>13s}")
    for name, values in times.items():
        rows[name] = {"min_s": round(min(values), 3),
                      "median_s": round(statistics.median(values), 3),
                      "cpu_median_s": round(statistics.median(cpu[name]), 3),
                      "runs_s": [round(v, 3) for v in values]}
        print(f"{name:36s} {min(values):7.3f} {statistics.median(values):9.3f} "
              f"{statistics.median(cpu[name]):13.3f}")
    result = {"machine": info, "repeat": opts.repeat, "commands": rows,
              "loadavg_at_end": [round(x, 2) for x in os.getloadavg()]}
    if simulated:
        sim = statistics.median(simulated)
        wall = rows["seqrun validate opsafe"]["median_s"]
        result["validate_opsafe"] = {"simulated_s": sim, "process_wall_s": wall,
                                     "ratio": round(sim / wall, 1), "goal": 50}
        print(f"\nvalidate opsafe: {sim:.2f} s simulated, whole process {wall:.3f} s: "
              f"{sim / wall:.0f}x (goal 50x)")
    write_json(opts.out, result)
    print(f"written {opts.out}")


if __name__ == "__main__":
    main()
