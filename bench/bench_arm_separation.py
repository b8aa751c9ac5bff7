"""Cost of the arm-against-arm check of one control cycle (seqrun/service/arm_separation.py).

Each cycle of each arm's loop in a campaign run calls ``ArmWatch.check`` with its reading:
the arm's speed from its last reading, both arms' capsules by forward kinematics (the
other arm at its latest reading), every capsule of one against every capsule of the other,
and each arm's stopping travel (reaction plus braking times its levers). This measures
that call for two LWA 3s facing each other (link volumes, no tools), both moving, 900 mm
apart (the capsules' bounding spheres prove them clear) and 260 mm apart (within their
stopping travel: every pair of capsules worked out exactly), on one core, and compares it with the 10 ms cycle of the 100 Hz loop. Goal: well
under 10 % of the cycle (the loop also reads the bus, checks guards and logs).

Run: ``.venv/bin/python bench/bench_arm_separation.py``
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from seqrun.arm.between_arms import base_transform  # noqa: E402
from seqrun.arm.description import load_arm  # noqa: E402
from seqrun.service.arm_separation import Separation  # noqa: E402
from seqrun.shipped import shipped_arm  # noqa: E402

CYCLE_S = 0.01
ROUNDS = 2000


def main() -> None:
    # apart (the bounding spheres decide), then close (every pair of capsules exactly)
    for gap_mm in (900.0, 260.0):
        one(gap_mm)


def one(gap_mm: float) -> None:
    arm = load_arm(shipped_arm("lwa3"))
    separation = Separation({"A": arm, "B": arm},
                            {"A": base_transform([0, 0, 0], [0, 0, 0]),
                             "B": base_transform([0, gap_mm, 0], [0, 0, 180])})
    a, b = separation.watch("A"), separation.watch("B")
    start = np.zeros(7)  # straight up
    rate = np.array([10.0, 8.0, 5.0, -6.0, 4.0, 3.0, 2.0])  # deg/s, both arms moving
    b.check(0.0, start, CYCLE_S)
    times = []
    for k in range(1, ROUNDS + 1):
        t = k * CYCLE_S
        q = start + rate * t * 0.01
        b.check(t, q, CYCLE_S)  # (the other arm's cycle, not timed)
        began = time.perf_counter()
        a.check(t, q, CYCLE_S)
        times.append(time.perf_counter() - began)
    per = np.array(times[100:]) * 1e6
    print(f"bases {gap_mm:g} mm apart: arm-against-arm check per cycle ({len(per)} cycles, 2 arms, "
          f"{len(separation._arms['A'].geometry.radii_mm)} volumes each):")
    print(f"  median {np.median(per):7.1f} us   p99 {np.percentile(per, 99):7.1f} us   "
          f"max {per.max():7.1f} us")
    print(f"  share of the {CYCLE_S * 1e3:g} ms cycle: median "
          f"{np.median(per) / (CYCLE_S * 1e6) * 100:.2f} %, p99 "
          f"{np.percentile(per, 99) / (CYCLE_S * 1e6) * 100:.2f} %")


if __name__ == "__main__":
    main()
