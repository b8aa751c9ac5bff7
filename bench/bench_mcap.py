"""run.mcap against the 100 Hz loop: the run folder with and without the MCAP writer.

Each run is ``seqrun run sequences/NAME.yaml --sim --yes`` in-process on the simulator in
real time, into a run folder (:func:`seqrun_runs.run_shipped`, the CLI's runner). In the
"off" runs the runner makes no run.mcap writer (as ``[ros] mcap = false``); in the "on"
runs it writes run.mcap as every run does (seqrun/service/mcap_log.py: a bounded queue fed
by the run log, a thread of its own). Runs alternate, the order flipping every pair, under
the same conditions. The loop period is the spacing of consecutive ``setpoint`` events
within a move (one per control cycle).

Reported per mode (all runs pooled): cycles, p50 / p99 / max period, p99 period error,
periods >= 12 ms, the process's CPU seconds per run, and for "on" run.mcap's size. Goal:
the "on" row matches the "off" one (p99 within 2 ms).

``--rt-priority N``: the loop's thread at SCHED_FIFO N, as ``seqrun run --rt-priority N``
(the writer thread then puts itself at SCHED_RR 1, below the loop): the figure on a host
that other work loads.

Run: ``python bench/bench_mcap.py [--pairs 2] [--sequence opsafe] [--rt-priority 10]``
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from loop_pairs import off_on_main, periods  # noqa: E402
from seqrun_runs import RESULTS, machine, run_shipped, write_json  # noqa: E402

from seqrun.clock import RealClock  # noqa: E402


def one_run(sequence: str, mcap: bool) -> dict:
    import seqrun.service.runner as runner

    setpoints: list = []

    def record(event) -> None:   # synchronous recorder: cheap, keeps the cycles only
        if event["type"] in ("setpoint", "step_started", "controlled_stop"):
            setpoints.append({"type": event["type"], "t": event["t"],
                              "step": event.get("step")})

    original = runner._mcap_log
    if not mcap:
        runner._mcap_log = lambda *args, **kwargs: None  # type: ignore[assignment]
    try:
        with tempfile.TemporaryDirectory() as tmp:
            cpu0 = time.process_time()
            run = run_shipped(sequence, RealClock(), log_dir=Path(tmp) / "run",
                              listeners=[record], html_report=False)
            cpu = time.process_time() - cpu0
            path = Path(tmp) / "run" / "run.mcap"
            size = path.stat().st_size if path.exists() else 0
    finally:
        runner._mcap_log = original   # type: ignore[assignment]
    return {"exit_code": run.result.exit_code, "periods": periods(setpoints),
            "dropped": 0, "cpu_s": cpu, "mcap_bytes": size}


def main() -> None:
    off_on_main(__doc__.splitlines()[0], one_run, label="run.mcap", key="mcap",
                extra="mcap_bytes", extra_unit=" B", results=RESULTS / "mcap.json",
                machine=machine, write_json=write_json)


if __name__ == "__main__":
    main()
