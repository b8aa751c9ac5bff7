"""The CPU of ``seqrun run --virtual-time`` against the dry run's for the same motion
(issue 42.8: within 1.3×).

    .venv/bin/python bench/bench_run_cpu.py [--rounds 5] [--sequences opsafe totem]
        [--out bench/results/run_cpu.json]

Each round runs, per sequence, as an operator types them, each its own process, side by
side in alternation (the same load for both):

  validate   ``seqrun validate FILE``: static checks and the dry run at virtual time
  run        ``seqrun run FILE --virtual-time --yes --plain --no-report --log-dir DIR``:
             the same motion on the simulator with the whole run folder written
             (trace.log.gz, events.jsonl, run.mcap, ...) but report.html, which is drawn
             after the motion (``seqrun report`` draws it later; its own figure below)
  run+html   the same with report.html drawn at the end

CPU is the child's user + system time (``os.wait4``), so the run.mcap writer's thread
counts. The ratio is of the medians; per round ratios show the spread.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_scaling import measure  # noqa: E402
from seqrun_runs import RESULTS, ROOT, machine, write_json  # noqa: E402

MODES = ("validate", "run", "run+html")


def argv(mode: str, sequence: Path, folder: Path) -> list[str]:
    seqrun = [sys.executable, "-m", "seqrun"]
    if mode == "validate":
        return [*seqrun, "validate", str(sequence)]
    return [*seqrun, "run", str(sequence), "--virtual-time", "--yes", "--plain",
            "--log-dir", str(folder), *(["--no-report"] if mode == "run" else [])]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--sequences", nargs="+", default=["opsafe", "totem"])
    parser.add_argument("--out", type=Path, default=RESULTS / "run_cpu.json")
    args = parser.parse_args()
    info = machine()
    cpu: dict[str, dict[str, list[float]]] = {s: {m: [] for m in MODES} for s in args.sequences}
    with tempfile.TemporaryDirectory(prefix="seqrun-bench-run-cpu-") as tmp:
        for round_ in range(args.rounds):
            for name in args.sequences:
                for mode in MODES:
                    folder = Path(tmp) / f"{name}-{mode}-{round_}"
                    figures = measure(argv(mode, ROOT / "sequences" / f"{name}.yaml", folder))
                    if figures["exit_code"] != 0:
                        raise SystemExit(f"{name} {mode} exited {figures['exit_code']}: "
                                         + " | ".join(figures["tail"]))
                    cpu[name][mode].append(figures["cpu_s"])
            print(f"round {round_ + 1} ({' / '.join(MODES)} CPU s): " + "; ".join(
                f"{n} " + " / ".join(f"{cpu[n][m][-1]:.2f}" for m in MODES)
                for n in args.sequences), flush=True)
    rows = []
    for name in args.sequences:
        med = {m: statistics.median(v) for m, v in cpu[name].items()}
        per_round = [round(r / v, 2) for r, v in zip(cpu[name]["run"], cpu[name]["validate"])]
        rows.append({"sequence": name, "cpu_s": cpu[name], "median_cpu_s": med,
                     "run_over_validate": round(med["run"] / med["validate"], 2),
                     "run_html_over_validate": round(med["run+html"] / med["validate"], 2),
                     "per_round_run_over_validate": per_round})
    write_json(args.out, {"machine": info, "load_avg_at_end": os.getloadavg(), "rows": rows})
    print("\n| sequence | validate CPU s | run --virtual-time CPU s | ratio | with report.html |")
    print("|---|---:|---:|---:|---:|")
    for r in rows:
        m = r["median_cpu_s"]
        print(f"| {r['sequence']} | {m['validate']:.2f} | {m['run']:.2f} | "
              f"{r['run_over_validate']:.2f}× (rounds {min(r['per_round_run_over_validate'])}-"
              f"{max(r['per_round_run_over_validate'])}) | {m['run+html']:.2f} s, "
              f"{r['run_html_over_validate']:.2f}× |")
    print(f"load average at start {info['loadavg_at_start']}, at end "
          f"{[round(x, 2) for x in os.getloadavg()]}; written to {args.out}")


if __name__ == "__main__":
    main()
