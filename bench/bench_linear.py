"""Executed straight-line deviation on the simulator: a 300 mm approach along the tool axis.

From Op-safe, ``move_linear`` 300 mm along the tool's -z at 20 mm/s (the capture approach),
run by the real executor against the simulated arm at virtual time (deterministic), at the
real control rate (100 Hz) and the dry-run rate (10 Hz), streamed as FSTEP (the arm file's
``cartesian.linear_command_mode: step``) and, for comparison, with the ramp law. The
deviation is the tool's distance from the line by forward kinematics of the measured joints
at every control cycle (what the run checks).

Goal (issue 14): <= 0.5 mm.

Run: ``.venv/bin/python bench/bench_linear.py [--out FILE]``
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from seqrun.arm.description import load_arm  # noqa: E402
from seqrun.service.dryrun import dry_run  # noqa: E402
from seqrun.sequence.loader import load_sequence

STEPS = """\
name: approach
description: 300 mm straight along the tool axis from Op-safe
steps:
  - reset
  - home
  - set_limits
  - move: totem
  - move: opsafe
  - move_linear: {position_mm: [0, 0, -300], relative: true, frame: tool, speed_mm_s: 20,
                  max_deviation_mm: 5}
"""


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path)
    args = parser.parse_args(argv)
    arm = load_arm(ROOT / "arms" / "lwa3.yaml")
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        project = Path(folder)
        (project / "poses").mkdir()
        for pose in (ROOT / "poses").glob("*.yaml"):
            (project / "poses" / pose.name).write_text(pose.read_text())
        (project / "sequences").mkdir()
        path = project / "sequences" / "approach.yaml"
        path.write_text(STEPS)
        loaded = load_sequence(path)
        park = {"j1": 0, "j2": -90, "j3": 0, "j4": -120.32, "j5": 0, "j6": 115.74, "j7": 0}
        for mode in ("step", "ramp"):
            variant = arm.model_copy(update={"cartesian": arm.cartesian.model_copy(
                update={"linear_command_mode": mode})})
            for hz in (100, 10):
                run = dry_run(loaded, variant, park, cycle_hz=hz)
                step = run.result.steps[-1]
                rows.append({"command_mode": mode, "cycle_hz": hz, "status": run.result.status,
                             "length_mm": step.detail.get("length_mm"),
                             "max_deviation_mm": step.detail.get("max_deviation_mm"),
                             "planned_s": step.planned_duration_s,
                             "executed_s": round(step.duration_s or 0.0, 3)})
    print("300 mm approach along the tool axis at 20 mm/s, simulator, virtual time:")
    for r in rows:
        print(f"  {r['command_mode']:4s} {r['cycle_hz']:3d} Hz: {r['status']:6s} largest deviation "
              f"{r['max_deviation_mm']} mm (planned {r['planned_s']:.2f} s, executed "
              f"{r['executed_s']:.2f} s)")
    if args.out:
        args.out.write_text(json.dumps(rows, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
