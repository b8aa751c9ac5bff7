"""The move cycle on the bus: one request in flight per module vs. the old full pipeline.

Issue 9.3: in ramp mode a cycle sends TargetVel and FRAMP_ACK to the same module; every
published PowerCube driver waits for a module's acknowledge before its next request, so the
client now keeps one request in flight per module (requests to other modules stay
pipelined). This bench measures, in virtual time on the simulated arm (exact 1 Mbit/s
wire timing, 100 µs module latency; deterministic, so one run each):

- the bus time of every move cycle (from the exchange's first frame to its last
  acknowledge), frames per cycle;
- executed / planned duration of every move, and of all moves together (goal <= 1.05);
- whether the run completes on modules that drop a request arriving while they are busy
  (``SEQRUN_SIM_OPTIONS=drop_request_while_busy``).

"before" is ``PowerCubeClient.ONE_REQUEST_PER_MODULE = False`` (the old sending), "after"
the default.

Run: ``.venv/bin/python bench/bench_cycle.py [--out bench/results/cycle.json]``
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from seqrun_runs import RESULTS, machine, run_shipped, write_json  # noqa: E402

from seqrun.clock import VirtualClock  # noqa: E402
from seqrun.powercube.client import PowerCubeClient  # noqa: E402
from seqrun.powercube.codec import SetMotion  # noqa: E402

SEQUENCES = ("opsafe", "totem")
RATIO_GOAL = 1.05


def measure(name: str, one_per_module: bool, drop_while_busy: bool = False) -> dict:
    PowerCubeClient.ONE_REQUEST_PER_MODULE = one_per_module
    cycles: list[tuple[float, int]] = []
    original = PowerCubeClient.transact_partial

    def timed(self, requests, timeout=None, **kwargs):
        t0 = self.clock.now()
        sent0 = self.stats.frames_sent
        try:
            return original(self, requests, timeout, **kwargs)
        finally:
            if any(isinstance(r, SetMotion) for r in requests):
                cycles.append((self.clock.now() - t0, self.stats.frames_sent - sent0))

    old_env = os.environ.get("SEQRUN_SIM_OPTIONS")
    if drop_while_busy:
        os.environ["SEQRUN_SIM_OPTIONS"] = "drop_request_while_busy"
    PowerCubeClient.transact_partial = timed
    try:
        run = run_shipped(name, VirtualClock())
    finally:
        PowerCubeClient.transact_partial = original
        PowerCubeClient.ONE_REQUEST_PER_MODULE = True
        if drop_while_busy:
            if old_env is None:
                del os.environ["SEQRUN_SIM_OPTIONS"]
            else:
                os.environ["SEQRUN_SIM_OPTIONS"] = old_env
    result = run.result
    moves = [s for s in result.steps if s.kind == "move" and s.status == "passed"]
    executed = sum(s.detail["executed_duration_s"] for s in moves)
    planned = sum(s.planned_duration_s for s in moves)
    times_ms = sorted(t * 1000 for t, _ in cycles)
    return {
        "sequence": name, "one_request_per_module": one_per_module,
        "drop_request_while_busy": drop_while_busy,
        "status": result.status, "message": result.message,
        "move_cycles": len(cycles),
        "cycle_bus_ms": {"mean": round(statistics.fmean(times_ms), 3) if times_ms else None,
                         "p50": round(times_ms[len(times_ms) // 2], 3) if times_ms else None,
                         "max": round(times_ms[-1], 3) if times_ms else None},
        "frames_per_cycle": round(statistics.fmean(n for _, n in cycles), 2) if cycles else None,
        "moves": [{"step": s.number, "planned_s": round(s.planned_duration_s, 4),
                   "executed_s": round(s.detail["executed_duration_s"], 4),
                   "ratio": round(s.detail["executed_duration_s"] / s.planned_duration_s, 4)}
                  for s in moves],
        "moves_ratio": round(executed / planned, 4) if planned else None,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=RESULTS / "cycle.json")
    args = parser.parse_args()
    rows = []
    for name in SEQUENCES:
        for one, drop in ((False, False), (True, False), (False, True), (True, True)):
            row = measure(name, one, drop)
            rows.append(row)
            label = "after " if one else "before"
            c = row["cycle_bus_ms"]
            print(f"{name:7s} {label} drop_while_busy={str(drop):5s} {row['status']:7s} "
                  f"cycles {row['move_cycles']:5d}  bus/cycle mean {c['mean']} ms p50 "
                  f"{c['p50']} max {c['max']}  frames/cycle {row['frames_per_cycle']}  "
                  f"moves executed/planned {row['moves_ratio']}"
                  + ("" if row["status"] == "passed" else f"  ({row['message'][:70]})"))
    ok = all(r["moves_ratio"] is not None and r["moves_ratio"] <= RATIO_GOAL
             for r in rows if r["one_request_per_module"])
    print(f"goal executed/planned <= {RATIO_GOAL} (after): {'met' if ok else 'NOT met'}")
    write_json(args.out, {"machine": machine(), "goal_ratio": RATIO_GOAL, "runs": rows})


if __name__ == "__main__":
    main()
