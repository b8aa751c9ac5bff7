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

sys.path.insert(0, str(Path(__file__).resolve().parent))

from loop_pairs import alternate, periods, row, summary  # noqa: E402
from seqrun_runs import RESULTS, machine, run_shipped, write_json  # noqa: E402

from seqrun.clock import RealClock  # noqa: E402


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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=2)
    ap.add_argument("--sequence", default="opsafe")
    args = ap.parse_args()
    runs = alternate(args.pairs, ("none", "slow"),
                     lambda mode: one_run(args.sequence, mode == "slow"))
    out = {"machine": machine(), "sequence": args.sequence,
           "no_subscriber": summary(runs["none"], 0.01),
           "slow_subscriber": summary(runs["slow"], 0.01)}
    for mode in ("no_subscriber", "slow_subscriber"):
        s = out[mode]
        print(f"{row(f'{mode:16s}', s)}  dropped {s['dropped_events']}  exit {s['exit_codes']}")
    write_json(RESULTS / "subscriber.json", out)


if __name__ == "__main__":
    main()
