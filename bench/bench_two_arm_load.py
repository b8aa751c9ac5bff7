"""Spurious faults of two-arm runs under load: ``seqrun run`` of a two-arm campaign on two
``seqrun sim serve``s with every core busy (issue 42, item 1).

The one-arm figure is ``bench_load_faults.py``'s; this is its two-arm twin. Each run starts
from two freshly powered-on simulated arms in Park (a new ``seqrun sim serve`` per arm and
run, each arm's zero recorded with ``seqrun zero set park --arm-id ID``), then runs a
sequence of examples/two-arms (default ``hold_and_approach.yaml``: both arms start up and
move at once, one holding while the other approaches it) with ``--yes --zero-confirmed
park``. Every run that does not pass
is a spurious fault (both arms were fine); its verdict, its fault's cause and the host
stalls its run folder recorded are kept.

Meanwhile ``--burners`` processes (default: one per core) spin at normal priority. seqrun
runs at normal priority unless ``--rt-priority N``; the simulators run at SCHED_FIFO 50 when
this process may (root or CAP_SYS_NICE), as modules are never descheduled.

Run: ``python bench/bench_two_arm_load.py [--runs 10] [--burners 2] [--rt-priority N]``
(about a minute per run). Writes bench/results/two_arm_load.json (or ``--out``).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_load_faults import (  # noqa: E402
    SEQRUN, SIM_PRIORITY, free_port, may_use_fifo, outcome, start_burners, wait_for_port)
from seqrun_runs import RESULTS, ROOT, machine, write_json  # noqa: E402

ARMS = ("A", "B")


def campaign(work: Path, ports: dict[str, int]) -> Path:
    """A copy of examples/two-arms whose arms are on ``sim serve``s at ``ports``."""
    folder = work / "two-arms"
    shutil.rmtree(folder, ignore_errors=True)
    shutil.copytree(ROOT / "examples" / "two-arms", folder)
    toml = (folder / "seqrun.toml").read_text(encoding="utf-8")
    for i, arm_id in enumerate(ARMS):
        bus = (f'bus = {{ interface = "socketcand", channel = "can{i}", kwargs = '
               f'{{ host = "127.0.0.1", port = {ports[arm_id]} }} }}')
        toml = re.sub(rf'(\[arms\.{arm_id}\]\narm = "lwa3"\n)# bus = [^\n]*\n',
                      rf"\g<1>{bus}\n", toml)
    if toml.count('interface = "socketcand"') != len(ARMS):
        raise RuntimeError("examples/two-arms/seqrun.toml changed: cannot place the buses")
    (folder / "seqrun.toml").write_text(toml, encoding="utf-8")
    return folder


def stalls(runs: Path) -> dict:
    """Host stalls (count, longest s) in every events.jsonl under ``runs``."""
    import gzip

    seconds = []
    for events in [*runs.rglob("events.jsonl"), *runs.rglob("events.jsonl.gz")]:
        opened = gzip.open(events, "rt", encoding="utf-8") if events.suffix == ".gz" \
            else events.open(encoding="utf-8")
        with opened as lines:
            for line in lines:
                if '"host_stall"' in line:
                    seconds.append(float(json.loads(line).get("seconds", 0.0)))
    return {"host_stalls": len(seconds), "longest_stall_s": max(seconds, default=0.0)}


def causes(runs: Path) -> list[str]:
    """The fault causes the runs' report.json files name."""
    found = []
    for report in runs.rglob("report.json"):
        fault = json.loads(report.read_text(encoding="utf-8")).get("fault") or {}
        if fault.get("cause"):
            found.append(f"{report.parent.name}: {fault['cause']}")
    return found


def one_run(work: Path, sequence: str, *, sim_fifo: bool, rt_priority: int | None,
            timeout_s: float) -> dict:
    state = work / "state"
    shutil.rmtree(state, ignore_errors=True)
    env = dict(os.environ, SEQRUN_STATE_DIR=str(state))
    ports = {a: free_port() for a in ARMS}
    sims = []
    try:
        for i, arm_id in enumerate(ARMS):
            serve = [SEQRUN, "sim", "serve", "--port", str(ports[arm_id]),
                     "--channel", f"can{i}"]
            if sim_fifo:
                serve = ["chrt", "-f", str(SIM_PRIORITY)] + serve
            sims.append(subprocess.Popen(serve, env=env, stdout=subprocess.DEVNULL,
                                         stderr=subprocess.DEVNULL))
        for arm_id in ARMS:
            wait_for_port(ports[arm_id])
        folder = campaign(work, ports)
        for arm_id in ARMS:
            subprocess.run([SEQRUN, "zero", "set", "park", "--yes", "--arm-id", arm_id],
                           cwd=folder, env=env, check=True, capture_output=True,
                           timeout=120)
        command = [SEQRUN, "run", f"sequences/{sequence}", "--yes", "--zero-confirmed",
                   "park", "--log-dir", str(work / "runs")]
        if rt_priority is not None:
            command += ["--rt-priority", str(rt_priority)]
        shutil.rmtree(work / "runs", ignore_errors=True)
        started = time.monotonic()
        done = subprocess.run(command, cwd=folder, env=env, capture_output=True, text=True,
                              timeout=timeout_s)
        result = outcome(done, time.monotonic() - started)
    finally:
        for sim in sims:
            sim.terminate()
        for sim in sims:
            sim.wait(10)
    result.update(stalls(work / "runs"))
    if result["exit"] != 0:
        result["causes"] = causes(work / "runs")
    return result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=10)
    parser.add_argument("--burners", type=int, default=os.cpu_count() or 2)
    parser.add_argument("--sequence", default="hold_and_approach.yaml")
    parser.add_argument("--rt-priority", type=int, default=None)
    parser.add_argument("--timeout", type=float, default=600.0)
    parser.add_argument("--out", type=Path, default=RESULTS / "two_arm_load.json")
    args = parser.parse_args()
    sim_fifo = may_use_fifo() and shutil.which("chrt") is not None
    print(f"simulators at {'SCHED_FIFO ' + str(SIM_PRIORITY) if sim_fifo else 'normal'} "
          f"priority; seqrun at {'SCHED_FIFO ' + str(args.rt_priority) if args.rt_priority else 'normal'} "
          f"priority; {args.burners} burner(s)", flush=True)
    burners = start_burners(args.burners)
    runs = []
    try:
        with tempfile.TemporaryDirectory(prefix="two-arm-load-") as tmp:
            for i in range(args.runs):
                result = one_run(Path(tmp), args.sequence, sim_fifo=sim_fifo,
                                 rt_priority=args.rt_priority, timeout_s=args.timeout)
                runs.append(result)
                print(f"run {i + 1}/{args.runs}: exit {result['exit']} "
                      f"({result['wall_s']:.1f} s, {result['host_stalls']} stalls, longest "
                      f"{result['longest_stall_s']:.3f} s) {result['verdict']}", flush=True)
    finally:
        for burner in burners:
            burner.kill()
    spurious = sum(1 for r in runs if r["exit"] != 0)
    print(f"spurious faults: {spurious} of {len(runs)}")
    write_json(args.out, {"goal": "0 spurious faults in 10 two-arm runs with every core busy",
                          "sequence": args.sequence, "burners": args.burners,
                          "sim_fifo": sim_fifo, "rt_priority": args.rt_priority,
                          "spurious": spurious, "runs": runs, "machine": machine()})
    return 0 if spurious == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
