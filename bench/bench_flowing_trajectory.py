"""A 50-point JointTrajectory of 5.0 s through the service layer (seqrun ros's path).

The trajectory (j1 +20°, j2 +10° along a minimum-jerk curve, positions only) is checked and
run by :func:`seqrun.service.trajectories.run_trajectory` on the simulated arm, once at
virtual time (deterministic) and once at the real clock (the host's load shows: every host
stall holds the plan). Printed: planned and executed duration of the motion, host stalls,
and the largest distance of the measured joints from each point at the cycle nearest its
time.

Goal (issue 41): 5.0 s ± one cycle (10 ms).

Run: ``.venv/bin/python bench/bench_flowing_trajectory.py``
"""

from __future__ import annotations

import gzip
import json
import math
import os
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from seqrun.arm.description import load_arm  # noqa: E402
from seqrun.clock import RealClock, VirtualClock  # noqa: E402
from seqrun.service import ArmSession  # noqa: E402
from seqrun.service.connection import open_connection  # noqa: E402
from seqrun.service.trajectories import (JointTrajectory, TrajectoryPoint,  # noqa: E402
                                         run_trajectory)


def one_run(clock, log_root: Path) -> dict:
    session = ArmSession(load_arm(ROOT / "arms" / "lwa3.yaml"),
                         open_connection(force_sim=True, clock=clock), status_hz=0,
                         log_root=log_root, poses_dir=ROOT / "poses")
    try:
        session.poll_status()
        assert session.arm_up().ok and session.home().ok
        session.poll_status()
        start = session.telemetry.joints_deg()
        points = []
        for i in range(1, 51):
            u = i / 50
            f = 10 * u**3 - 15 * u**4 + 6 * u**5
            points.append(TrajectoryPoint((math.radians(start["j1"] + 20 * f),
                                           math.radians(start["j2"] + 10 * f)), 5.0 * u))
        result = run_trajectory(session, JointTrajectory(("j1", "j2"), tuple(points)),
                                by="bench").wait(timeout=120)
        with gzip.open(result.run_dir / "events.jsonl.gz", "rt", encoding="utf-8") as handle:
            log = [json.loads(line) for line in handle]
        (finished,) = [e for e in log if e["type"] == "step_finished"]
        setpoints = [e for e in log if e["type"] == "setpoint"]

        def nearest(t: float) -> dict:  # the cycle closest to a point's time
            return min(setpoints, key=lambda e: abs(e["plan_t"] - t))

        worst = max(abs(nearest(p.time_from_start_s)["measured_deg"][j]
                        - math.degrees(p.positions_rad[j])) for p in points for j in (0, 1))
        return {"ok": result.ok, "planned_s": finished["planned_duration_s"],
                "executed_s": round(finished["executed_duration_s"], 4),
                "host_stalls": sum(e["type"] == "host_stall" for e in log),
                "worst_point_error_deg": round(worst, 3)}
    finally:
        session.close()


def main() -> int:
    with tempfile.TemporaryDirectory() as folder:
        rows = {"virtual time": one_run(VirtualClock(), Path(folder) / "v"),
                "real clock": one_run(RealClock(), Path(folder) / "r")}
    load = os.getloadavg()[0]
    for name, row in rows.items():
        print(f"{name:13s} {json.dumps(row)}")
    print(f"load {load:.1f}")
    return 0 if all(r["ok"] for r in rows.values()) else 1


if __name__ == "__main__":
    raise SystemExit(main())
