"""report.html of a 10-minute run: size and build time (goal: a few MB, seconds).

1. Synthesises a 10-minute run folder at virtual time: ``seqrun run --virtual-time`` of a
   generated sequence (start-up, Park -> Totem, then Totem <-> Op-safe at velocity_scale
   0.3 with 2-s dwells until >= 600 s of motion and waits), 100 Hz loop, full run folder.
   Sizes of the folder's files are virtual-time results: deterministic.
2. Builds report.html from the folder ``--repeat`` times (``seqrun.report.write_html``,
   in process, matplotlib imported once before timing) and the CSV export once; reports
   wall and CPU seconds (median) and the page's size. Time depends on the host's load.

Run: ``.venv/bin/python bench/bench_report.py [--repeat 3] [--minutes 10] [--keep DIR]``
(``--keep DIR`` reuses a run folder synthesised before, or leaves the new one there).
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from seqrun_runs import RESULTS, ROOT, machine, median, write_json  # noqa: E402

GOAL_MB = 5.0          # "a few MB"
GOAL_BUILD_S = 10.0    # "seconds"


def make_project(root: Path, minutes: float) -> Path:
    """A project tree with the shipped arm, poses and start-up, and a long sequence."""
    for name in ("arms", "poses"):
        shutil.copytree(ROOT / name, root / name)
    (root / "sequences").mkdir()
    shutil.copy(ROOT / "sequences" / "startup.yaml", root / "sequences")
    steps = ["  - include: startup.yaml",
             "  - move: {pose: totem, velocity_scale: 0.5, label: Up to Totem}"]
    # Totem <-> Op-safe at 0.3: ~8 s each way, plus 2-s dwells; ~20.5 s per round trip.
    rounds = int(minutes * 60 / 20) + 1
    for k in range(rounds):
        steps += [f"  - move: {{pose: opsafe, velocity_scale: 0.3, label: out {k + 1}}}",
                  "  - wait: {seconds: 2}",
                  f"  - move: {{pose: totem, velocity_scale: 0.3, label: back {k + 1}}}",
                  "  - wait: {seconds: 2}"]
    path = root / "sequences" / "long.yaml"
    path.write_text(f"name: Long run\ndescription: {minutes:g} minutes of Totem <-> Op-safe "
                    "for the report bench\nsteps:\n" + "\n".join(steps) + "\n")
    return path


def synthesise(folder: Path, minutes: float) -> float:
    """Run the long sequence into ``folder``; returns the wall seconds it took."""
    with tempfile.TemporaryDirectory(prefix="seqrun-bench-report-") as tmp:
        sequence = make_project(Path(tmp), minutes)
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, "-m", "seqrun", "run", str(sequence),
                               "--virtual-time", "--yes", "--plain", "--no-report",
                               "--log-dir", str(folder)],
                              capture_output=True, text=True, check=False)
        wall = time.perf_counter() - t0
    if proc.returncode != 0:
        sys.exit(f"the synthesised run failed (exit {proc.returncode}):\n{proc.stdout}{proc.stderr}")
    return wall


def sizes(folder: Path) -> dict[str, int]:
    return {p.name: p.stat().st_size for p in sorted(folder.iterdir()) if p.is_file()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--keep", type=Path, help="run folder to reuse or keep")
    parser.add_argument("--out", type=Path, default=RESULTS / "report.json")
    args = parser.parse_args()

    import json

    import matplotlib.figure  # noqa: F401  (imported once, outside the timings)

    from seqrun.report import export_csv, load_run, write_html

    info = machine()
    tmp = None
    if args.keep is not None and (args.keep / "events.jsonl").is_file():
        folder, synth_wall = args.keep, None
    else:
        if args.keep is not None:
            folder = args.keep
        else:
            tmp = tempfile.TemporaryDirectory(prefix="seqrun-bench-run-")
            folder = Path(tmp.name) / "run"
        synth_wall = synthesise(folder, args.minutes)
    try:
        report = json.loads((folder / "report.json").read_text())
        walls, cpus = [], []
        for _ in range(args.repeat):
            w0, c0 = time.perf_counter(), time.process_time()
            page = write_html(folder)
            walls.append(time.perf_counter() - w0)
            cpus.append(time.process_time() - c0)
        w0 = time.perf_counter()
        data = load_run(folder)
        load_s = time.perf_counter() - w0
        with tempfile.TemporaryDirectory() as csv_dir:
            w0 = time.perf_counter()
            paths = export_csv(folder, csv_dir, data=data)
            csv_s = time.perf_counter() - w0
            csv_sizes = {p.name: p.stat().st_size for p in paths}
        html = page.read_text(encoding="utf-8")
        svg_bytes = sum(len(m) for m in re.findall(r"<svg.*?</svg>", html, re.S))
        result = {
            "machine": info,
            "run": {"simulated_s": report.get("duration_s"), "steps": len(report.get("steps", [])),
                    "arm_readings": data.reading_count, "events": data.event_count,
                    "synthesis_wall_s": None if synth_wall is None else round(synth_wall, 1)},
            "folder_bytes": sizes(folder),
            "report_html_bytes": page.stat().st_size,
            "report_svg_bytes": svg_bytes,
            "build_wall_s": [round(x, 2) for x in walls],
            "build_cpu_s": [round(x, 2) for x in cpus],
            "build_wall_s_median": round(median(walls), 2),
            "build_cpu_s_median": round(median(cpus), 2),
            "load_run_wall_s": round(load_s, 2),
            "csv_wall_s": round(csv_s, 2), "csv_bytes": csv_sizes,
            "goals": {"report_html_mb": GOAL_MB, "build_s": GOAL_BUILD_S},
        }
    finally:
        if tmp is not None:
            tmp.cleanup()
    write_json(args.out, result)
    mb = result["report_html_bytes"] / 1e6
    print(f"run: {result['run']['simulated_s']:.0f} s simulated, {result['run']['steps']} steps, "
          f"{result['run']['arm_readings']} arm readings")
    print("folder: " + ", ".join(f"{k} {v / 1e6:.2f} MB" for k, v in result["folder_bytes"].items()))
    print(f"report.html: {mb:.2f} MB (goal < {GOAL_MB:g} MB: "
          f"{'met' if mb < GOAL_MB else 'NOT met'}); build median {result['build_wall_s_median']} s "
          f"wall, {result['build_cpu_s_median']} s CPU (goal < {GOAL_BUILD_S:g} s: "
          f"{'met' if result['build_wall_s_median'] < GOAL_BUILD_S else 'NOT met'}); "
          f"loader alone {result['load_run_wall_s']} s")
    print(f"CSV: {result['csv_wall_s']} s, " + ", ".join(
        f"{k} {v / 1e6:.1f} MB" for k, v in csv_sizes.items()))
    print(f"load average at start: {info['loadavg_at_start']}; written to {args.out}")


if __name__ == "__main__":
    main()
