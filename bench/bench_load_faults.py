"""Spurious faults under load: ``seqrun run`` on ``seqrun sim serve`` with every core busy.

Issue 23 item 7. A run must tell "the module did not answer" from "this process was not
scheduled". Two kinds of run, each from a freshly powered-on simulated arm in Park (a new
``seqrun sim serve`` per run, its zero recorded with ``seqrun zero set park``):

- healthy runs (``--runs``, default 20) of a sequence (default ``sequences/opsafe.yaml``):
  every run that does not pass is a spurious fault (the arm was fine);
- silent-module runs (``--silent-runs``, default 5): module ``--silent-module`` stops
  answering (the simulator's ``missing`` fault, ``--silent-at`` seconds after the run
  opened its bus) while the arm moves; these run on the built-in simulator (``--sim``),
  whose clock starts with the run and whose answers are on the wire when the modules
  sent them, however late this loaded host reads them. The run must fault;
  the detection time is read from the run's own CAN trace: from the first request to the
  silent module that got no answer to seqrun's Halt on the bus (and, as an upper bound,
  from that module's last answer).

Meanwhile ``--burners`` processes (default: one per core) spin at normal priority, the
"other work" on the operator's PC. seqrun runs as an operator would start it (normal
priority unless ``--rt-priority N``). The simulator stands in for modules that are never
descheduled: it runs at SCHED_FIFO priority 50 when this process may (root or
CAP_SYS_NICE; said in the output), else at normal priority (then a late answer may be the
simulator's and the figure says so).

Run: ``.venv/bin/python bench/bench_load_faults.py [--runs 20] [--silent-runs 5]
[--watchdog] [--burners 2]`` (about 30 s per run). Writes bench/results/load_faults.json
(or ``--out``).
"""

from __future__ import annotations

import argparse
import gzip
import json
import os
import re
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "bench" / "results"
SEQRUN = str(Path(sys.executable).with_name("seqrun"))
SIM_PRIORITY = 50
HALT = 0x02
LINE = re.compile(r"\((?P<t>[\d.]+)\) \S+ (?P<id>[0-9A-F]{3})#(?P<data>[0-9A-F]*) (?P<dir>[TR])")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for_port(port: int, timeout: float = 30.0) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.5):
                return
        except OSError:
            time.sleep(0.1)
    raise RuntimeError(f"sim serve did not listen on {port}")


def may_use_fifo() -> bool:
    try:
        old = os.sched_getscheduler(0), os.sched_getparam(0)
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
        os.sched_setscheduler(0, old[0], old[1])
        return True
    except (OSError, AttributeError):
        return False


def start_burners(n: int) -> list[subprocess.Popen]:
    return [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]


def arm_file(folder: Path, watchdog: bool) -> Path:
    """The shipped arm file, with the modules' watchdog switched on if asked."""
    import yaml

    data = yaml.safe_load((ROOT / "arms" / "lwa3.yaml").read_text())
    data.setdefault("can", {}).setdefault("watchdog", {})["enabled"] = watchdog
    path = folder / "lwa3.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def detection(trace: Path, module: int) -> dict | None:
    """Times from the silent module's first unanswered request (and from its last answer)
    to seqrun's first Halt, from the run's candump trace."""
    last_answer = None
    first_unanswered = None
    halt = None
    with gzip.open(trace, "rt") as lines:
        for line in lines:
            m = LINE.match(line)
            if m is None:
                continue
            t, can_id, data, way = float(m["t"]), int(m["id"], 16), m["data"], m["dir"]
            if way == "R" and can_id == 0x0A0 + module:
                last_answer, first_unanswered = t, None
            elif way == "T" and can_id in (0x0C0 + module, 0x0E0 + module):
                if first_unanswered is None:
                    first_unanswered = t
            elif (way == "T" and data[:2] == f"{HALT:02X}"
                  and (can_id == 0x100 or 0x0E1 <= can_id <= 0x0FF)):
                if first_unanswered is not None:
                    halt = t
                    break
    if halt is None or first_unanswered is None or last_answer is None:
        return None
    return {"from_first_unanswered_ms": round((halt - first_unanswered) * 1e3, 1),
            "from_last_answer_ms": round((halt - last_answer) * 1e3, 1)}


def silent_run(work: Path, sequence: Path, arm: Path, fault: str, *, rt_priority: int | None,
               timeout_s: float) -> dict:
    """A run on the built-in simulator (real time) whose module goes silent: its clock
    starts with the run, so the fault's time falls in the moves however slowly this loaded
    host starts a process, and its answers are on the wire when the modules sent them
    (a stall of this process delays their reading, not their sending), as on the arm."""
    runs = work / "runs"
    shutil.rmtree(runs, ignore_errors=True)
    command = [SEQRUN, "run", str(sequence), "--sim", "--yes", "--sim-fault", fault,
               "--arm", str(arm), "--log-dir", str(runs)]
    if rt_priority is not None:
        command += ["--rt-priority", str(rt_priority)]
    started = time.monotonic()
    done = subprocess.run(command, capture_output=True, text=True, timeout=timeout_s)
    return outcome(done, time.monotonic() - started)


def one_run(work: Path, sequence: Path, arm: Path, *, sim_fifo: bool,
            rt_priority: int | None, timeout_s: float) -> dict:
    """A healthy run on a fresh ``seqrun sim serve`` (its zero recorded first)."""
    state = work / "state"
    runs = work / "runs"
    shutil.rmtree(state, ignore_errors=True)
    shutil.rmtree(runs, ignore_errors=True)
    env = dict(os.environ, SEQRUN_STATE_DIR=str(state))
    port = free_port()
    serve = [SEQRUN, "sim", "serve", "--port", str(port)]
    if sim_fifo:
        serve = ["chrt", "-f", str(SIM_PRIORITY)] + serve
    sim = subprocess.Popen(serve, env=env, stdout=subprocess.DEVNULL,
                           stderr=subprocess.DEVNULL)
    try:
        wait_for_port(port)
        bus = ["-i", "socketcand", "-c", "can0", "--bus-kwargs", "host=127.0.0.1",
               "--bus-kwargs", f"port={port}"]
        subprocess.run([SEQRUN, "zero", "set", "park", "--yes", "--arm", str(arm), *bus],
                       env=env, check=True, capture_output=True, timeout=120)
        command = [SEQRUN, "run", str(sequence), "--yes", "--zero-confirmed", "park",
                   "--arm", str(arm), "--log-dir", str(runs), *bus]
        if rt_priority is not None:
            command += ["--rt-priority", str(rt_priority)]
        started = time.monotonic()
        done = subprocess.run(command, env=env, capture_output=True, text=True,
                              timeout=timeout_s)
        wall = time.monotonic() - started
    finally:
        sim.terminate()
        sim.wait(10)
    return outcome(done, wall)


def outcome(done: subprocess.CompletedProcess, wall: float) -> dict:
    lines = [line for line in done.stdout.splitlines() if line.strip()]
    verdict = next((line for line in reversed(lines) if "(exit " in line and ":" in line),
                   lines[-1] if lines else "")
    result = {"exit": done.returncode, "verdict": str(verdict).strip(), "wall_s": round(wall, 2)}
    if done.returncode != 0 and not any("fault" in line.lower() for line in lines):
        result["output"] = (lines + done.stderr.splitlines())[-4:]
    if done.returncode != 0:
        result["why"] = [line.strip() for line in lines if "error" in line.lower()
                         or "fault" in line.lower()][-3:]
    return result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--silent-runs", type=int, default=5)
    parser.add_argument("--silent-module", type=int, default=4)
    parser.add_argument("--silent-at", type=float, nargs="+", default=[5.0, 8.0, 11.0],
                        help="seconds after the run opened its bus (during the moves)")
    parser.add_argument("--sequence", type=Path, default=ROOT / "sequences" / "opsafe.yaml")
    parser.add_argument("--burners", type=int, default=os.cpu_count() or 2)
    parser.add_argument("--watchdog", action="store_true",
                        help="switch the modules' watchdog on in the arm file")
    parser.add_argument("--rt-priority", type=int, default=None)
    parser.add_argument("--out", type=Path, default=RESULTS / "load_faults.json")
    parser.add_argument("--keep", type=Path, default=None,
                        help="copy the run folder of every healthy run that failed here")
    args = parser.parse_args()

    sim_fifo = may_use_fifo() and shutil.which("chrt") is not None
    work = Path(tempfile.mkdtemp(prefix="seqrun-load-"))
    arm = arm_file(work, args.watchdog)
    burners = start_burners(args.burners)
    healthy: list[dict] = []
    silent: list[dict] = []
    load_before = os.getloadavg()
    try:
        for i in range(args.runs):
            r = one_run(work, args.sequence, arm, sim_fifo=sim_fifo,
                        rt_priority=args.rt_priority, timeout_s=300)
            healthy.append(r)
            if r["exit"] != 0 and args.keep is not None:
                shutil.copytree(work / "runs", args.keep / f"healthy-{i + 1}",
                                dirs_exist_ok=True)
            print(f"healthy {i + 1}/{args.runs}: exit {r['exit']} {r['wall_s']} s "
                  f"{r.get('why', '')}", flush=True)
        for i in range(args.silent_runs):
            at = args.silent_at[i % len(args.silent_at)]
            r = silent_run(work, args.sequence, arm, f"{args.silent_module}:missing@{at}",
                           rt_priority=args.rt_priority, timeout_s=300)
            trace = next((work / "runs").rglob("trace.log.gz"), None)
            r["detection"] = detection(trace, args.silent_module) if trace else None
            r["silent_at_s"] = at
            if r["detection"] is None and args.keep is not None and (work / "runs").is_dir():
                shutil.copytree(work / "runs", args.keep / f"silent-{i + 1}", dirs_exist_ok=True)
            silent.append(r)
            print(f"silent {i + 1}/{args.silent_runs}: exit {r['exit']} "
                  f"{r['detection']}", flush=True)
    finally:
        for b in burners:
            b.kill()
        shutil.rmtree(work, ignore_errors=True)
    spurious = sum(1 for r in healthy if r["exit"] != 0)
    detected = [r for r in silent if r["exit"] != 0 and r["detection"]]
    worst = max((r["detection"]["from_first_unanswered_ms"] for r in detected), default=None)
    worst_upper = max((r["detection"]["from_last_answer_ms"] for r in detected), default=None)
    summary = {
        "sequence": str(args.sequence.relative_to(ROOT)) if args.sequence.is_relative_to(ROOT)
        else str(args.sequence),
        "watchdog": args.watchdog, "burners": args.burners,
        "seqrun_priority": f"SCHED_FIFO {args.rt_priority}" if args.rt_priority else "normal",
        "simulator_priority": f"SCHED_FIFO {SIM_PRIORITY}" if sim_fifo else "normal",
        "load_before": [round(x, 2) for x in load_before],
        "load_after": [round(x, 2) for x in os.getloadavg()],
        "healthy_runs": len(healthy), "spurious_faults": spurious,
        "silent_runs": len(silent), "silent_detected": len(detected),
        "worst_detection_ms": worst, "worst_detection_from_last_answer_ms": worst_upper,
        "goal": "0 spurious faults; every silent module detected within 100 ms",
        "goal_met": spurious == 0 and len(detected) == len(silent)
        and worst is not None and worst <= 100.0,
        "healthy": healthy, "silent": silent,
        "when": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(summary, indent=1) + "\n")
    print(json.dumps({k: v for k, v in summary.items() if k not in ("healthy", "silent")},
                     indent=1))
    return 0 if summary["goal_met"] else 1


if __name__ == "__main__":
    sys.exit(main())
