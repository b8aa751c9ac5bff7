"""A slow subscriber against the 100 Hz loop: no subscriber vs one that sleeps 1 s per event.

Each run is ``seqrun run sequences/NAME.yaml --sim --yes`` in-process on the simulator in
real time (:func:`seqrun_runs.run_shipped`, the same runner as the CLI). In the "slow" runs a
subscriber on the executor's event hub sleeps 1 s in its callback for every event it gets
(its own queue, its own thread: typed events, seqrun/events.py). Runs alternate (the order
flips every pair) under the same conditions. The loop period is the spacing of consecutive
``setpoint`` events within a move (one per control cycle), recorded by a synchronous recorder
in both modes.

Reported per mode (all runs pooled): cycles, p50 / p99 / max period, p99 period error
(|period - 10 ms|), periods >= 12 ms, and for the slow mode how many events its queue
dropped. The goal: the slow row matches the plain one.

Run: ``python bench/bench_subscriber.py [--pairs 2] [--sequence opsafe]``
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from seqrun_runs import RESULTS, machine, run_shipped, write_json  # noqa: E402

from seqrun.clock import RealClock  # noqa: E402


def periods(events: list) -> list[float]:
    """Spacing (s) of consecutive setpoints of the same step (one per cycle)."""
    out, prev = [], None
    for e in events:
        if e["type"] != "setpoint":
            prev = None if e["type"] in ("step_started", "controlled_stop") else prev
            continue
        if prev is not None and prev[0] == e.get("step"):
            out.append(e["t"] - prev[1])
        prev = (e.get("step"), e["t"])
    return out


def one_run(sequence: str, slow: bool) -> dict:
    setpoints: list = []

    def record(event) -> None:  # synchronous recorder: cheap, keeps setpoints only
        if event.type in ("setpoint", "step_started", "controlled_stop"):
            setpoints.append(event)

    subscribers = []

    def attach(executor) -> None:
        executor.listeners.append(record)
        if slow:
            subscribers.append(executor.events.add_listener(
                lambda event: time.sleep(1.0), "sleeps 1 s per event", maxsize=1000))

    # run_shipped has no on_executor: the recorder is a listener that attaches the slow
    # subscriber on the first event (run_started, before the preflight reads the arm).
    attached = {"done": False}

    def first(event) -> None:
        if not attached["done"]:
            attached["done"] = True
            attach(first.executor)  # type: ignore[attr-defined]

    import seqrun.service.runner as runner

    original = runner.build_executor

    def build(*args, **kwargs):
        executor, client = original(*args, **kwargs)
        first.executor = executor  # type: ignore[attr-defined]
        return executor, client

    runner.build_executor = build
    try:
        run = run_shipped(sequence, RealClock(), listeners=[first])
    finally:
        runner.build_executor = original
    dropped = sum(s.dropped for s in subscribers)
    for s in subscribers:
        s.subscription.close()
    p = periods(setpoints)
    return {"exit_code": run.result.exit_code, "periods": p, "dropped": dropped}


def summary(runs: list[dict], cycle_s: float) -> dict:
    p = np.array([x for r in runs for x in r["periods"]])
    err = np.abs(p - cycle_s)
    return {"runs": len(runs), "exit_codes": [r["exit_code"] for r in runs],
            "cycles": int(len(p)),
            "p50_ms": round(float(np.percentile(p, 50)) * 1e3, 3),
            "p99_ms": round(float(np.percentile(p, 99)) * 1e3, 3),
            "max_ms": round(float(p.max()) * 1e3, 3),
            "p99_error_ms": round(float(np.percentile(err, 99)) * 1e3, 3),
            "over_12ms": int((p >= 0.012).sum()),
            "dropped_events": sum(r["dropped"] for r in runs)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=2)
    ap.add_argument("--sequence", default="opsafe")
    args = ap.parse_args()
    runs: dict[str, list] = {"none": [], "slow": []}
    for k in range(args.pairs):
        order = ("none", "slow") if k % 2 == 0 else ("slow", "none")
        for mode in order:
            runs[mode].append(one_run(args.sequence, mode == "slow"))
    out = {"machine": machine(), "sequence": args.sequence,
           "no_subscriber": summary(runs["none"], 0.01),
           "slow_subscriber": summary(runs["slow"], 0.01)}
    for mode in ("no_subscriber", "slow_subscriber"):
        s = out[mode]
        print(f"{mode:16s} cycles {s['cycles']:5d}  p50 {s['p50_ms']:.2f} ms  p99 "
              f"{s['p99_ms']:.2f} ms  max {s['max_ms']:.2f} ms  p99 error "
              f"{s['p99_error_ms']:.2f} ms  >=12 ms {s['over_12ms']}  dropped "
              f"{s['dropped_events']}  exit {s['exit_codes']}")
    write_json(RESULTS / "subscriber.json", out)


if __name__ == "__main__":
    main()
