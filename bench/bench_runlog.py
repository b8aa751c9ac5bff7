"""Cost of the run folder per step: flat from 100 to 10,000 steps.

report.json used to be rewritten whole after every step (every step's result in it), so a
10,000-step sequence cost O(n²): 33 s of CPU and 534 MB of writes. Now a finished step is
one line appended to steps.jsonl, and the running report.json (constant size) is rewritten
at most once a second; the whole report is written once, at the end.

This feeds a :class:`seqrun.service.runlog.RunLog` the events of ``N`` finished steps (as the
executor emits them, with a few CAN frames and setpoint events per step, no bus, no arm)
and measures, per step, the CPU time and the bytes written while the run goes, then the
final report separately. The per-step figures should not grow with N.

Run: ``.venv/bin/python bench/bench_runlog.py [--steps 100 1000 10000]``
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import can  # noqa: E402

from seqrun.runfolder import logfile  # noqa: E402
from seqrun.clock import VirtualClock  # noqa: E402
from seqrun.results import RunResult, StepResult
from seqrun.service.runlog import RunLog  # noqa: E402

FRAMES_PER_STEP = 14       # one cycle of a 7-module arm: 7 requests, 7 acknowledges
SETPOINTS_PER_STEP = 1


def feed(folder: Path, steps: int) -> dict:
    written = [0]
    real_write = logfile._write

    def counting(fd, data):
        n = real_write(fd, data)
        written[0] += n
        return n

    logfile._write = counting
    try:
        clock = VirtualClock()
        frame = can.Message(arbitration_id=0x0C1, data=b"\x0a\x3c", is_extended_id=False)
        cpu0 = time.process_time()
        log = RunLog(folder, {"sequence": "bench"}, clock=clock, channel="can0")
        log.on_event({"t": 0.0, "type": "run_started", "steps": steps, "clock_s": 0.0})
        results = []
        for n in range(1, steps + 1):
            log.on_event({"t": clock.now(), "type": "step_started", "step": n, "kind": "wait",
                          "label": f"step {n}", "location": f"bench.yaml:{n}:5"})
            for _ in range(FRAMES_PER_STEP):
                frame.timestamp = clock.now()
                log.on_frame(frame)
            for _ in range(SETPOINTS_PER_STEP):
                log.on_event({"t": clock.now(), "type": "setpoint", "step": n, "plan_t": 0.0,
                              "planned_deg": [0.0] * 7, "measured_deg": [0.0] * 7})
            clock.sleep(0.01)
            log.on_event({"t": clock.now(), "type": "step_finished", "step": n,
                          "status": "passed", "duration_s": 0.01, "planned_duration_s": None})
            results.append(StepResult(n, "wait", f"step {n}", f"bench.yaml:{n}:5", "passed",
                                      n * 0.01, n * 0.01 + 0.01))
        cpu_running = time.process_time() - cpu0
        bytes_running = written[0]
        log.finish(RunResult("passed", 0, "sequence completed", results, 0.0, clock.now()))
        log.close()
        cpu_total = time.process_time() - cpu0
    finally:
        logfile._write = real_write
    return {"steps": steps,
            "cpu_per_step_us": round(cpu_running / steps * 1e6, 1),
            "bytes_per_step": round(bytes_running / steps, 1),
            "final_report_cpu_ms": round((cpu_total - cpu_running) * 1e3, 2),
            "final_bytes": written[0] - bytes_running,
            "folder_bytes": sum(p.stat().st_size for p in folder.iterdir())}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, nargs="+", default=[100, 1000, 10000])
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for steps in args.steps:
            rows.append(feed(Path(tmp) / str(steps), steps))
    print(f"{'steps':>7} {'CPU/step µs':>12} {'bytes/step':>11} {'final ms':>9} "
          f"{'final bytes':>12} {'folder bytes':>13}")
    for r in rows:
        print(f"{r['steps']:>7} {r['cpu_per_step_us']:>12} {r['bytes_per_step']:>11} "
              f"{r['final_report_cpu_ms']:>9} {r['final_bytes']:>12} {r['folder_bytes']:>13}")
    print(json.dumps({"load_avg": os.getloadavg(), "rows": rows}))


if __name__ == "__main__":
    main()
