"""Velocity jogs on a busy host: does the modules' watchdog trip? (issue 43, item 5)

``seqrun jog`` streams FVEL setpoints with the modules' watchdog armed: a host that does
not refresh it within the modules' timeout (about 50 ms) stops the joint with
HALTED|ERROR|COMM_ERROR. That is right for a host that died, and a spurious stop for one
that was only busy. Each try: a fresh ``seqrun sim serve`` (at SCHED_FIFO 50 where this
process may: it stands in for modules that are never descheduled), its zero recorded, the
arm reset, homed and limited (``sequences/startup.yaml``), then ``seqrun jog j1 10 --for
SECONDS`` while ``--burners`` processes (default: one per core) spin at normal priority.
A try that does not end "jog ... done" with exit 0 counts, and the ones whose modules
report COMM_ERROR (the watchdog) are counted apart. Once at normal priority, once with
``--rt-priority N``.

Run: ``.venv/bin/python bench/bench_jog.py [--tries 9] [--seconds 3] [--rt-priority 20]``
(about 20 s per try). Writes bench/results/jog_load.json (or ``--out``).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

from bench_load_faults import (RESULTS, ROOT, SEQRUN, SIM_PRIORITY, free_port,
                               may_use_fifo, start_burners, wait_for_port)


def one_try(work: Path, *, seconds: float, rt_priority: int | None, sim_fifo: bool,
            burners: int) -> dict:
    """A jog on a freshly served, homed arm with ``burners`` busy processes beside it."""
    state = work / "state"
    shutil.rmtree(state, ignore_errors=True)
    env = dict(os.environ, SEQRUN_STATE_DIR=str(state), SEQRUN_RUNTIME_DIR=str(work / "rt"))
    port = free_port()
    serve = [SEQRUN, "sim", "serve", "--port", str(port)]
    if sim_fifo:
        serve = ["chrt", "-f", str(SIM_PRIORITY)] + serve
    sim = subprocess.Popen(serve, env=env, stdout=subprocess.DEVNULL,
                           stderr=subprocess.DEVNULL)
    spinning: list[subprocess.Popen] = []
    try:
        wait_for_port(port)
        bus = ["-i", "socketcand", "-c", "can0", "--bus-kwargs", "host=127.0.0.1",
               "--bus-kwargs", f"port={port}"]
        for setup in ([SEQRUN, "zero", "set", "park", "--yes", *bus],
                      [SEQRUN, "run", str(ROOT / "sequences" / "startup.yaml"), "--yes",
                       "--plain", "--no-report", "--zero-confirmed", "park", "--log-dir",
                       str(work / "runs"), *bus]):
            prepared = subprocess.run(setup, env=env, capture_output=True, text=True,
                                      timeout=180)
            if prepared.returncode != 0:   # not a jog: said apart, not counted
                return {"setup_failed": " ".join(setup[1:3]),
                        "output": (prepared.stdout + prepared.stderr).splitlines()[-3:]}
        spinning = start_burners(burners)
        command = [SEQRUN, "jog", "j1", "10", "--for", str(seconds), *bus]
        if rt_priority is not None:
            command += ["--rt-priority", str(rt_priority)]
        started = time.monotonic()
        done = subprocess.run(command, env=env, capture_output=True, text=True,
                              timeout=120)
        wall = time.monotonic() - started
    finally:
        for burner in spinning:
            burner.kill()
            burner.wait()
        sim.terminate()
        sim.wait(10)
    lines = [line for line in (done.stdout + done.stderr).splitlines() if line.strip()]
    return {"exit": done.returncode, "last": lines[-1] if lines else "",
            "watchdog": any("COMM_ERROR" in line for line in lines),
            "wall_s": round(wall, 2)}


def series(work: Path, args: argparse.Namespace, rt_priority: int | None,
           sim_fifo: bool) -> dict:
    tries = []
    for index in range(args.tries):
        tries.append(one_try(work, seconds=args.seconds, rt_priority=rt_priority,
                             sim_fifo=sim_fifo, burners=args.burners))
        print(f"  {'rt' if rt_priority else 'normal'} try {index + 1}: {tries[-1]}",
              flush=True)
    jogs = [t for t in tries if "setup_failed" not in t]
    return {"rt_priority": rt_priority, "tries": len(jogs),
            "failed": sum(t["exit"] != 0 for t in jogs),
            "watchdog_trips": sum(t["watchdog"] for t in jogs), "runs": tries}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tries", type=int, default=9)
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--rt-priority", type=int, default=20)
    parser.add_argument("--burners", type=int, default=os.cpu_count() or 2)
    parser.add_argument("--only", choices=("normal", "rt"), default=None)
    parser.add_argument("--out", type=Path, default=RESULTS / "jog_load.json")
    args = parser.parse_args()
    sim_fifo = may_use_fifo()
    work = Path(tempfile.mkdtemp(prefix="bench-jog-"))
    try:
        result = {"date": time.strftime("%Y-%m-%d %H:%M:%S"), "burners": args.burners,
                  "seconds": args.seconds, "sim_fifo": sim_fifo,
                  "load_before": os.getloadavg()[0]}
        for kind in ("normal", "rt"):
            if args.only in (None, kind):
                result[kind] = series(work, args, args.rt_priority if kind == "rt" else None,
                                      sim_fifo)
        result["load_after"] = os.getloadavg()[0]
    finally:
        shutil.rmtree(work, ignore_errors=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1))
    for kind in ("normal", "rt"):
        if kind in result:
            r = result[kind]
            print(f"{kind}: {r['failed']} of {r['tries']} jogs failed, "
                  f"{r['watchdog_trips']} by the watchdog")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
