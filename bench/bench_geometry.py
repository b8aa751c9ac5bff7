"""Collision distance per configuration: link capsules against the arm file's obstacles
and each other (seqrun/arm/geometry.py), single configurations and batched.

Every pair's clearance is computed (``Geometry.clearances``) for N random configurations
inside the joint limits (batched: one call for all N); single = ``Geometry.smallest`` of
one configuration, the run-time check of every control cycle (plain floats when every
obstacle is a plane). With ``--mock`` a box and a cylinder (a target mock and a pillar) are added
to the arm file's obstacles, so the golden-section search paths are timed too.

Goal (issue 14): <= 100 µs per configuration batched. Times are wall-clock on one core
and indicative on a shared machine.

Run: ``.venv/bin/python bench/bench_geometry.py [--n 2000] [--mock] [--out FILE]``
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from seqrun.arm.description import ArmDescription, load_arm  # noqa: E402
from seqrun.arm.geometry import Geometry  # noqa: E402


def with_mock(arm: ArmDescription) -> ArmDescription:
    data = arm.model_dump()
    data["geometry"]["obstacles"] += [
        {"name": "target_mock", "box": {"center_mm": [-150, 450, 100],
                                        "size_mm": [200, 200, 200], "rpy_deg": [0, 0, 30]}},
        {"name": "pillar", "cylinder": {"base_mm": [600, 0, 0], "radius_mm": 80,
                                        "height_mm": 1500}}]
    return ArmDescription.model_validate(data)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=2000)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--mock", action="store_true", help="add a box and a cylinder")
    parser.add_argument("--out", type=Path)
    args = parser.parse_args(argv)
    arm = load_arm(ROOT / "arms" / "lwa3.yaml")
    if args.mock:
        arm = with_mock(arm)
    geometry = Geometry(arm)
    limits = np.radians([j.limits_deg for j in arm.joints])
    q = np.random.default_rng(14).uniform(limits[:, 0], limits[:, 1], (args.n, arm.dof))
    _, names = geometry.clearances(q[:2])
    batched, single = [], []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        geometry.clearances(q)
        batched.append((time.perf_counter() - t0) / args.n)
        t0 = time.perf_counter()
        for row in q[:200]:
            geometry.smallest(row)  # the run-time check of one measured configuration
        single.append((time.perf_counter() - t0) / 200)
    result = {"configurations": args.n, "pairs": len(names), "obstacles":
              [o.name for o in arm.geometry.obstacles], "load_average": os.getloadavg(),
              "batched_us_per_configuration": round(min(batched) * 1e6, 2),
              "single_us_per_configuration": round(min(single) * 1e6, 1)}
    print(f"{len(names)} pairs ({', '.join(result['obstacles'])}), {args.n} configurations, "
          f"best of {args.repeat} (load average {result['load_average'][0]:.1f}; indicative):")
    print(f"  batched {result['batched_us_per_configuration']:8.2f} µs per configuration "
          "(goal <= 100)")
    print(f"  single  {result['single_us_per_configuration']:8.1f} µs per configuration")
    if args.out:
        args.out.write_text(json.dumps(result, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
