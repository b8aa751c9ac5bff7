"""How seqrun scales with the length of a sequence: time, peak RSS, run-folder size.

    .venv/bin/python bench/bench_scaling.py [--moves 10 100 1000 5000]
        [--commands static validate run] [--out bench/results/scaling.json] [--keep DIR]

For each N a sequence is generated in a temporary project (the shipped arm, poses and
start-up): the start-up, Park -> Totem, then N moves of j1 alternating between +10° and
-10° (about 1.3 s each). Each command runs as its own process, exactly as an operator
types it:

  static    ``seqrun validate --static FILE``
  validate  ``seqrun validate FILE`` (the dry run on the simulator at virtual time)
  run       ``seqrun run FILE --virtual-time --yes --plain --log-dir DIR`` (full run
            folder, report.html drawn at the end)

and is measured from outside: wall time, peak resident set (``ru_maxrss`` of that process
from ``os.wait4``) and, for ``run``, the size of the run folder per file. A figure is
"linear or better" when its value per move does not grow with N (the table gives the ratio
of each N's per-move figure to the smallest N's, for N >= 100: below that the process's
start-up dominates). Time depends on the host's load (reported); RSS and folder sizes
do not.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from seqrun_runs import RESULTS, ROOT, machine, write_json  # noqa: E402

COMMANDS = ("static", "validate", "run")


def make_project(root: Path, moves: int) -> Path:
    """A project with the shipped arm, poses and start-up and a sequence of ``moves`` moves."""
    for name in ("arms", "poses"):
        shutil.copytree(ROOT / name, root / name, dirs_exist_ok=True)
    (root / "sequences").mkdir(exist_ok=True)
    shutil.copy(ROOT / "sequences" / "startup.yaml", root / "sequences")
    lines = [f"name: Alternating {moves}",
             f"description: {moves} moves of j1 between +10 and -10 degrees (bench_scaling)",
             "steps:", "  - include: startup.yaml",
             "  - move: {pose: totem, velocity_scale: 0.5, label: Up to Totem}"]
    for k in range(moves):
        angle = 10 if k % 2 == 0 else -10
        lines.append(f"  - move: {{joints: {{j1: {angle}}}, label: swing {k + 1}}}")
    path = root / "sequences" / f"alternating-{moves}.yaml"
    path.write_text("\n".join(lines) + "\n")
    return path


def measure(argv: list[str]) -> dict:
    """Run ``argv``; wall seconds, peak RSS (MB), exit code and the last lines of output."""
    t0 = time.perf_counter()
    with tempfile.TemporaryFile() as out:
        proc = subprocess.Popen(argv, stdout=out, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        tail = out.read().decode(errors="replace").splitlines()[-3:]
    return {"wall_s": round(wall, 2), "cpu_s": round(usage.ru_utime + usage.ru_stime, 2),
            "peak_rss_mb": round(usage.ru_maxrss / 1024, 1), "exit_code": proc.returncode,
            "tail": tail}


def folder_bytes(folder: Path) -> dict[str, int]:
    return {str(p.relative_to(folder)): p.stat().st_size
            for p in sorted(folder.rglob("*")) if p.is_file()}


def command_line(command: str, sequence: Path, run_dir: Path) -> list[str]:
    seqrun = [sys.executable, "-m", "seqrun"]
    if command == "static":
        return [*seqrun, "validate", "--static", str(sequence)]
    if command == "validate":
        return [*seqrun, "validate", str(sequence)]
    return [*seqrun, "run", str(sequence), "--virtual-time", "--yes", "--plain",
            "--log-dir", str(run_dir)]


def bench(moves: int, commands: list[str], work: Path) -> list[dict]:
    project = work / f"n{moves}"
    sequence = make_project(project, moves)
    rows = []
    for command in commands:
        run_dir = project / "run"
        figures = measure(command_line(command, sequence, run_dir))
        row = {"moves": moves, "command": command, **figures}
        if command == "run" and run_dir.is_dir():
            files = folder_bytes(run_dir)
            row["folder_bytes"] = sum(files.values())
            row["files"] = files
            report = json.loads((run_dir / "report.json").read_text())
            row["motion_s"] = report.get("duration_s")
        if figures["exit_code"] != 0:
            print(f"  warning: {command} N={moves} exited {figures['exit_code']}: "
                  + " | ".join(figures["tail"]), file=sys.stderr)
        rows.append(row)
        print(f"  N={moves:>5} {command:<9} {row['wall_s']:>8.1f} s "
              f"{row['peak_rss_mb']:>8.1f} MB"
              + (f" {row['folder_bytes'] / 1e6:>9.1f} MB folder" if "folder_bytes" in row
                 else ""), flush=True)
    return rows


def per_move_ratios(rows: list[dict]) -> dict[str, dict[str, list]]:
    """Per command and figure: (N, figure / N relative to the first N >= 100)."""
    out: dict[str, dict[str, list]] = {}
    for command in COMMANDS:
        mine = [r for r in rows if r["command"] == command and r["moves"] >= 100]
        if len(mine) < 2:
            continue
        out[command] = {}
        for key in ("wall_s", "cpu_s", "peak_rss_mb", "folder_bytes"):
            if key not in mine[0]:
                continue
            base = mine[0][key] / mine[0]["moves"]
            out[command][key] = [(r["moves"], round(r[key] / r["moves"] / base, 2))
                                 for r in mine]
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--moves", type=int, nargs="+", default=[10, 100, 1000, 5000])
    parser.add_argument("--commands", nargs="+", choices=COMMANDS, default=list(COMMANDS))
    parser.add_argument("--out", type=Path, default=RESULTS / "scaling.json")
    parser.add_argument("--keep", type=Path, help="leave the projects and run folders here")
    args = parser.parse_args()

    info = machine()
    if args.keep is not None:
        args.keep.mkdir(parents=True, exist_ok=True)
        work, tmp = args.keep, None
    else:
        tmp = tempfile.TemporaryDirectory(prefix="seqrun-bench-scaling-")
        work = Path(tmp.name)
    rows: list[dict] = []
    try:
        for moves in args.moves:
            rows += bench(moves, args.commands, work)
    finally:
        if tmp is not None:
            tmp.cleanup()
    result = {"machine": info, "load_avg_at_end": os.getloadavg(), "rows": rows,
              "per_move_relative": per_move_ratios(rows)}
    write_json(args.out, result)

    print(f"\n| command | N | time (s) | CPU (s) | peak RSS (MB) | run folder (MB) |")
    print("|---|---:|---:|---:|---:|---:|")
    for r in rows:
        size = f"{r['folder_bytes'] / 1e6:.1f}" if "folder_bytes" in r else "–"
        print(f"| {r['command']} | {r['moves']:,} | {r['wall_s']:.1f} | {r['cpu_s']:.1f} | "
              f"{r['peak_rss_mb']:.0f} | {size} |")
    for command, figures in result["per_move_relative"].items():
        print(f"{command}: per move, relative to N={figures['wall_s'][0][0]}: " + "; ".join(
            f"{k} " + " ".join(f"{ratio:g}" for _, ratio in v) for k, v in figures.items()))
    print(f"load average at start {info['loadavg_at_start']}, at end "
          f"{[round(x, 2) for x in os.getloadavg()]}; written to {args.out}")


if __name__ == "__main__":
    main()
