"""The executor on the simulated arm: plan fidelity, dry-run speed, 100 Hz loop jitter.

1. Executed / planned duration of every move of ``sequences/opsafe.yaml`` and
   ``sequences/totem.yaml`` (per step ``executed_duration_s / planned_duration_s`` from the
   run report; total = sum over the moves, and the report's ``duration_s /
   planned_duration_s``, which also counts start-up, waits, dwell and checkpoint), in
   virtual time and in real time. Goal: <= 1.05 per move and in total.
2. Dry-run speed: simulated seconds / wall seconds of ``seqrun run --virtual-time`` (run
   folder written, 100 Hz loop) for opsafe and totem, and of the ``seqrun validate`` dry
   run (``seqrun.service.dryrun.dry_run``, when present) at the arm file's loop rate (100 Hz since
   issue 29: the run's rate, so its figures are the run's), side by side with the same dry
   run at 10 Hz (the rate it had before issue 29). Goal >= 100x in process at the arm's
   rate (issue 29; it was 200x at 10 Hz). cProfile of each (top 15 by tottime) goes to
   ``bench/results/dryrun_profile.txt``.
3. The 100 Hz setpoint loop in real time (during the real-time runs of 1, one process,
   nothing else of this bench running): every cycle's start is taken where the executor
   wakes from ``clock.sleep_until`` in its streaming loop (a recording clock); period error
   = time between consecutive cycle starts - 10 ms, overruns (cycles that missed their slot)
   included; the same measured on the wire from the run's CAN trace (time between
   consecutive setpoint requests to one module); also the lateness of each wake-up and
   the spacing of the ``setpoint`` events' ``t``. Goal: p99 |period error| < 2 ms.

Run: ``.venv/bin/python bench/bench_executor.py [--repeat 3] [--virtual-only]``
"""

from __future__ import annotations

import argparse
import cProfile
import io
import itertools
import json
import os
import pstats
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from seqrun_runs import (RESULTS, ROOT, load_shipped, machine, median,  # noqa: E402
                         run_shipped, write_json)

from seqrun.clock import RealClock, VirtualClock  # noqa: E402

SEQUENCES = ("opsafe", "totem")
#: The ``seqrun`` program installed beside the interpreter that runs this benchmark (any
#: virtual environment, not only the checkout's ``.venv``).
SEQRUN = Path(sys.executable).with_name("seqrun")
RATIO_GOAL = 1.05
SPEED_GOAL = 100.0
#: The dry run's rate before issue 29, measured beside the arm's rate.
OLD_DRY_RUN_HZ = 10.0
JITTER_GOAL_MS = 2.0


class RecordingClock(RealClock):
    """Real time; remembers when the executor's streaming loop asked to wake and woke."""

    def __init__(self) -> None:
        self.wakes: list[tuple[float, float, float]] = []   # (stream start, target, woke)

    def sleep_until(self, t: float) -> None:
        super().sleep_until(t)
        caller = sys._getframe(1)
        while caller is not None and caller.f_code.co_name in ("idle_until", "idle"):
            caller = caller.f_back  # the executor sleeps through its idle-hook wrapper
        if caller is not None and caller.f_code.co_name == "stream":
            self.wakes.append((caller.f_locals.get("t_start", 0.0), t, time.monotonic()))


def move_ratios(result) -> dict:
    moves = [s for s in result.steps if s.kind == "move"]
    per = [{"step": s.number, "label": s.label,
            "planned_s": round(s.planned_duration_s, 4),
            "executed_s": round(s.detail["executed_duration_s"], 4),
            "ratio": round(s.detail["executed_duration_s"] / s.planned_duration_s, 4)}
           for s in moves if s.planned_duration_s]
    planned = sum(m["planned_s"] for m in per)
    executed = sum(m["executed_s"] for m in per)
    return {"moves": per, "motion_ratio": round(executed / planned, 4),
            "report_duration_s": round(result.duration_s, 4),
            "report_planned_s": round(result.planned_duration_s, 4),
            "report_ratio": round(result.duration_s / result.planned_duration_s, 4)}


def _pct(values) -> dict | None:
    if not values:
        return None
    a = np.abs(np.array(values)) * 1e3
    return {"n": len(values), "p50_ms": round(float(np.percentile(a, 50)), 4),
            "p99_ms": round(float(np.percentile(a, 99)), 4),
            "max_ms": round(float(a.max()), 4),
            "over_2ms": int((a >= 2.0).sum())}


def trace_periods(trace: Path, cycle: float) -> list[float]:
    """Period errors of the setpoint loop read from the CAN trace itself: the time between
    consecutive FRAMP/FSTEP requests to the same module (one per module per cycle) within one
    move (a gap of more than 20 cycles starts a new move). This times the frames the modules
    receive, not the executor's wake-ups."""
    import can
    from seqrun.powercube.codec import SetMotion, decode_request
    from seqrun.powercube.protocol import MotionMode
    setpoint_modes = {MotionMode.FRAMP_ACK, MotionMode.FRAMP, MotionMode.FSTEP_ACK,
                      MotionMode.FSTEP}
    last: dict[int, float] = {}
    errors: list[float] = []
    for msg in can.LogReader(str(trace)):
        if not 0x0E0 <= msg.arbitration_id < 0x100:
            continue
        try:
            req = decode_request(msg.arbitration_id, bytes(msg.data))
        except Exception:  # noqa: BLE001 - a trace may hold anything; not a setpoint then
            continue
        if not isinstance(req, SetMotion) or req.mode not in setpoint_modes:
            continue
        prev = last.get(req.module)
        last[req.module] = msg.timestamp
        if prev is not None and msg.timestamp - prev < 20 * cycle:
            errors.append(msg.timestamp - prev - cycle)
    return errors


def loop_stats(clock: RecordingClock, events: list[dict], cycle: float,
               trace: Path | None = None) -> dict:
    """Every period counts, overruns included: a cycle that woke two slots late is a period
    error of one cycle or more, not a period left out."""
    periods, late = [], []
    skipped = 0
    for (s0, t0, w0), (s1, t1, w1) in itertools.pairwise(clock.wakes):
        late.append(w1 - t1)
        if s1 != s0:            # a new move: no period across streams
            continue
        slots = round((t1 - t0) / cycle)
        if slots != 1:
            skipped += slots - 1
        periods.append(w1 - w0 - cycle)
    spacing = []
    setpoints = [e for e in events if e["type"] == "setpoint"]
    for a, b in itertools.pairwise(setpoints):
        if a.get("step") == b.get("step"):
            spacing.append(b["t"] - a["t"] - cycle)
    return {"cycles": len(clock.wakes), "skipped_slots": skipped,
            "period_error": _pct(periods), "wake_lateness": _pct(late),
            "setpoint_spacing_error": _pct(spacing),
            "trace_period_error": _pct(trace_periods(trace, cycle)) if trace else None}


def fidelity(clock_name: str, repeat: int, log_root: Path) -> dict:
    out = {}
    for name in SEQUENCES:
        runs = []
        for i in range(repeat):
            clock = VirtualClock() if clock_name == "virtual" else RecordingClock()
            run = run_shipped(name, clock, log_dir=log_root / f"{clock_name}-{name}-{i}",
                              keep_events=clock_name == "real")
            if run.result.status != "passed":
                raise SystemExit(f"{name} ({clock_name}) did not pass: {run.result.message}")
            entry = move_ratios(run.result)
            if clock_name == "real":
                _, arm = load_shipped(name)
                entry["loop"] = loop_stats(
                    clock, run.events, 1.0 / arm.control.cycle_hz,
                    trace=log_root / f"{clock_name}-{name}-{i}" / "trace.log")
            runs.append(entry)
        med_moves = [{**m, "ratio": median([r["moves"][k]["ratio"] for r in runs]),
                      "executed_s": median([r["moves"][k]["executed_s"] for r in runs])}
                     for k, m in enumerate(runs[0]["moves"])]
        out[name] = {"moves": med_moves,
                     "motion_ratio": median([r["motion_ratio"] for r in runs]),
                     "report_ratio": median([r["report_ratio"] for r in runs]),
                     "report_duration_s": median([r["report_duration_s"] for r in runs]),
                     "report_planned_s": runs[0]["report_planned_s"], "runs": runs}
    return out


def _profile_text(title: str, profile: cProfile.Profile, n: int = 15) -> str:
    buf = io.StringIO()
    stats = pstats.Stats(profile, stream=buf)
    stats.sort_stats("tottime").print_stats(n)
    by_tottime = buf.getvalue()
    buf = io.StringIO()
    pstats.Stats(profile, stream=buf).sort_stats("cumulative").print_stats(n)
    cumulative = buf.getvalue().split("Ordered by:", 1)[-1]
    return (f"==== {title}\n---- top {n} by tottime\n{by_tottime}\n"
            f"---- top {n} by cumulative time (for orientation)\nOrdered by:{cumulative}\n")


def _validate_dry_run():
    """The ``seqrun validate`` dry run, if this checkout has one: a function of the loaded
    sequence (loading is not part of what it times)."""
    try:
        from seqrun.service.dryrun import dry_run
    except ImportError:
        return None
    from seqrun.defaults import START_POSE
    from seqrun.arm.poses import pose_joints_deg

    def run(loaded, arm, cycle_hz=None):
        start = pose_joints_deg(START_POSE, loaded.poses_dir)
        return dry_run(loaded, arm, start, start_pose=START_POSE, cycle_hz=cycle_hz)
    return run


def _cli(args: list[str]) -> float:
    """Wall seconds of one ``seqrun`` process (interpreter start and imports included)."""
    w = time.perf_counter()
    proc = subprocess.run([str(SEQRUN), *args], cwd=ROOT, capture_output=True, text=True,
                          check=False)
    wall = time.perf_counter() - w
    if proc.returncode != 0:
        raise SystemExit(f"seqrun {' '.join(args)} exited {proc.returncode}:\n"
                         f"{proc.stdout[-2000:]}{proc.stderr[-2000:]}")
    _cli.last_stdout = proc.stdout
    return wall


def dry_run_speed(repeat: int, log_root: Path) -> tuple[dict, str]:
    """Speed of ``run --virtual-time`` and of the validate dry run, in process (warm:
    median of ``repeat`` after the first) and as whole CLI processes (cold)."""
    out: dict = {}
    profiles = []
    for name in SEQUENCES:
        runs = []
        for i in range(repeat):
            clock = VirtualClock()
            run = run_shipped(name, clock, log_dir=log_root / f"dry-{name}-{i}")
            runs.append((run.clock_s, run.wall_s))
        prof = cProfile.Profile()
        clock = VirtualClock()
        prof.enable()
        run = run_shipped(name, clock, log_dir=log_root / f"dry-{name}-profiled")
        prof.disable()
        profiles.append(_profile_text(
            f"seqrun run sequences/{name}.yaml --virtual-time (100 Hz, run folder; sequence "
            f"loading included): {run.clock_s:.2f} simulated s in {run.wall_s:.2f} wall s "
            f"under cProfile", prof))
        out[f"run --virtual-time {name}"] = {
            "simulated_s": round(runs[0][0], 4), "wall_s": round(median([w for _, w in runs]), 4),
            "speedup": round(median([c / w for c, w in runs]), 1),
            "speedups": [round(c / w, 1) for c, w in runs]}
    validate = _validate_dry_run()
    for name in SEQUENCES:
        key = f"validate dry run {name}"
        if validate is None:
            out[key] = None
            continue
        loaded, arm = load_shipped(name)
        validate(loaded, arm)  # warm (the codec's and the wire's tables)
        # The arm's rate and the old 10 Hz alternately, so that both see the same load.
        runs, old = [], []
        for _ in range(repeat):
            runs.append(validate(loaded, arm))
            old.append(validate(loaded, arm, OLD_DRY_RUN_HZ))
        prof = cProfile.Profile()
        prof.enable()
        profiled = validate(loaded, arm)
        prof.disable()
        profiles.append(_profile_text(
            f"seqrun validate dry run of sequences/{name}.yaml (seqrun.service.dryrun.dry_run, "
            f"{profiled.cycle_hz:g} Hz): {profiled.simulated_s:.2f} simulated s in "
            f"{profiled.wall_s:.2f} wall s under cProfile", prof))
        for label, rows in ((key, runs), (f"{key} at {OLD_DRY_RUN_HZ:g} Hz (before)", old)):
            out[label] = {"simulated_s": round(rows[0].simulated_s, 4),
                          "wall_s": round(median([r.wall_s for r in rows]), 4),
                          "speedup": round(median([r.speedup for r in rows]), 1),
                          "speedups": [round(r.speedup, 1) for r in rows],
                          "cycle_hz": rows[0].cycle_hz, "passed": rows[0].passed}
    # Whole processes, as an operator or CI runs them.
    for name in SEQUENCES:
        walls, simulated = [], None
        for i in range(repeat):
            folder = log_root / f"cli-{name}-{i}"
            walls.append(_cli(["run", f"sequences/{name}.yaml", "--sim", "--yes",
                               "--virtual-time", "--plain", "--log-dir", str(folder)]))
            simulated = json.loads((folder / "report.json").read_text())["duration_s"]
        out[f"CLI: seqrun run --virtual-time {name}"] = {
            "simulated_s": simulated, "wall_s": round(median(walls), 4),
            "speedup": round(simulated / median(walls), 1), "process": True}
        if validate is None:
            continue
        walls = [_cli(["validate", f"sequences/{name}.yaml", "--json"]) for _ in range(repeat)]
        report = json.loads(_cli.last_stdout)["dry_run"]
        out[f"CLI: seqrun validate {name}"] = {
            "simulated_s": report["simulated_s"], "wall_s": round(median(walls), 4),
            "speedup": round(report["simulated_s"] / median(walls), 1), "process": True,
            "dry_run_wall_s": report["wall_s"], "dry_run_speedup": report["speedup"]}
    return out, "".join(profiles)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="repetitions (median reported)")
    parser.add_argument("--virtual-only", action="store_true",
                        help="skip the real-time runs (fidelity in real time, loop jitter)")
    parser.add_argument("--real-only", action="store_true",
                        help="only the real-time runs (fidelity in real time, loop jitter)")
    parser.add_argument("--out", type=Path, default=None,
                        help="JSON file (default bench/results/executor.json, "
                             "executor_real_only.json with --real-only)")
    args = parser.parse_args()
    info = machine()
    with tempfile.TemporaryDirectory(prefix="bench-executor-") as tmp:
        root = Path(tmp)
        fid = {"virtual": fidelity("virtual", 1, root)}
        speed, profile = ({}, None) if args.real_only else dry_run_speed(args.repeat, root)
        if not args.virtual_only:
            load_before = os.getloadavg()
            fid["real"] = fidelity("real", args.repeat, root)
            loads = {"before": [round(x, 2) for x in load_before],
                     "after": [round(x, 2) for x in os.getloadavg()]}

    ok = True
    print(f"1. executed / planned ruckig duration (goal <= {RATIO_GOAL}); real time: median "
          f"of {args.repeat}")
    header = (f"{'sequence':<9}{'step':<37}{'planned s':>10}"
              + "".join(f"{c + ' exec s':>15}{c + ' ratio':>14}" for c in fid))
    print(header)
    print("-" * len(header))
    for name in SEQUENCES:
        for k, m in enumerate(fid["virtual"][name]["moves"]):
            cells = "".join(f"{fid[c][name]['moves'][k]['executed_s']:>15.3f}"
                            f"{fid[c][name]['moves'][k]['ratio']:>14.4f}" for c in fid)
            ok &= all(fid[c][name]["moves"][k]["ratio"] <= RATIO_GOAL for c in fid)
            print(f"{name:<8}{m['step']:>2} {m['label'][:35]:<35}{m['planned_s']:>10.3f}{cells}")
        planned = sum(m["planned_s"] for m in fid["virtual"][name]["moves"])
        cells = "".join(f"{'':>15}{fid[c][name]['motion_ratio']:>14.4f}" for c in fid)
        ok &= all(fid[c][name]["motion_ratio"] <= RATIO_GOAL for c in fid)
        print(f"{name:<8}{'   all moves':<38}{planned:>10.3f}{cells}")
        cells = "".join(f"{fid[c][name]['report_duration_s']:>15.3f}"
                        f"{fid[c][name]['report_ratio']:>14.4f}" for c in fid)
        print(f"{name:<8}{'   report duration_s / planned':<38}"
              f"{fid['virtual'][name]['report_planned_s']:>10.3f}{cells}")
    print("   (the report's duration also counts start-up, settle, the 1 s dwell and the "
          "checkpoint; the goal applies to the moves)")

    if speed:
        print(f"\n2. dry-run speed: simulated s / wall s (goal >= {SPEED_GOAL:g}x for the "
              f"validate dry run in process at the arm's rate), median of {args.repeat}; "
              f"load average {[round(x, 2) for x in os.getloadavg()]}")
        header = f"{'run':<52}{'simulated s':>12}{'wall s':>9}{'speedup':>10}"
        print(header)
        print("-" * len(header))
        for key, r in speed.items():
            if r is None:
                print(f"{key:<52}{'(no dry run in this checkout)':>31}")
                continue
            print(f"{key:<52}{r['simulated_s']:>12.2f}{r['wall_s']:>9.3f}{r['speedup']:>9.1f}x")
        print("   in process: the run only (sequence already loaded), warm (median of the "
              "repeats);\n   CLI: the whole process, interpreter start, imports and loading "
              "included")
        print(f"   profile (cProfile, top 15 by tottime): {RESULTS / 'dryrun_profile.txt'}")

    if "real" in fid:
        print(f"\n3. 100 Hz setpoint loop in real time (goal p99 |period error| < "
              f"{JITTER_GOAL_MS:g} ms); all real-time runs pooled per sequence")
        header = (f"{'sequence':<10}{'cycles':>8}{'skipped':>8}  {'metric':<28}"
                  f"{'p50 ms':>9}{'p99 ms':>9}{'max ms':>9}{'>=2 ms':>8}")
        print(header)
        print("-" * len(header))
        for name in SEQUENCES:
            runs = fid["real"][name]["runs"]
            cycles = sum(r["loop"]["cycles"] for r in runs)
            skipped = sum(r["loop"]["skipped_slots"] for r in runs)
            for metric, label in (("period_error", "  |period - 10 ms|"),
                                  ("trace_period_error", "  |FRAMP dt - 10 ms| (trace)"),
                                  ("wake_lateness", "  wake-up lateness"),
                                  ("setpoint_spacing_error", "  |setpoint dt - 10 ms|")):
                p = [r["loop"][metric] for r in runs if r["loop"][metric]]
                if not p:
                    continue
                row = {k: median([x[k] for x in p]) for k in ("p50_ms", "p99_ms", "max_ms")}
                row["max_ms"] = max(x["max_ms"] for x in p)
                row["over_2ms"] = sum(x["over_2ms"] for x in p)
                if metric == "period_error":
                    ok &= row["p99_ms"] < JITTER_GOAL_MS
                print(f"{name:<10}{cycles:>8}{skipped:>8}{label:<30}{row['p50_ms']:>9.3f}"
                      f"{row['p99_ms']:>9.3f}{row['max_ms']:>9.3f}{row['over_2ms']:>8}")
        print("   p50/p99: median over the runs; max: the worst run; >=2 ms: periods off by 2 ms"
              " or more, all runs.\n   Overruns (skipped slots) are inside the percentiles; the"
              " trace row times the frames the\n   modules receive (one FRAMP per module per "
              "cycle), the others the executor's wake-ups.")
        print(f"   load average (1, 5, 15 min) before the real-time runs {loads['before']}, "
              f"after {loads['after']} ({os.cpu_count()} CPUs); {info['scheduling']}")
    # The goal is the dry run's own speed; the other rows (the 100 Hz --virtual-time run,
    # whole processes: bench_startup.py's goal) are shown beside it.
    speed_ok = all(r is None or r["speedup"] >= SPEED_GOAL for key, r in speed.items()
                   if key.startswith("validate dry run") and "(before)" not in key)
    print(f"\ngoals: fidelity/jitter {'met' if ok else 'NOT met'}, dry-run speed "
          f"{('met' if speed_ok else 'NOT met') if speed else 'not measured'}")

    if profile is not None:
        (RESULTS / "dryrun_profile.txt").write_text(
            f"# bench/bench_executor.py, {info['date']}, commit {info['commit']} "
            f"(uncommitted seqrun files: {', '.join(info['uncommitted_seqrun_files']) or 'none'})"
            f", Python {info['python']}, {info['cpus']} CPUs\n\n" + profile)
    for clock_name in fid:  # keep the JSON readable: drop per-run loop dumps' duplicates
        for name in SEQUENCES:
            fid[clock_name][name]["runs"] = [
                {k: v for k, v in r.items() if k != "moves"} for r in fid[clock_name][name]["runs"]]
    out = args.out or RESULTS / ("executor_real_only.json" if args.real_only
                                 else "executor.json")
    write_json(out, {
        "benchmark": "bench_executor", "machine": info, "repeat": args.repeat,
        "command": "python bench/bench_executor.py " + " ".join(sys.argv[1:]),
        "fidelity": fid, "dry_run_speed": speed,
        "loadavg_real_time_runs": loads if "real" in fid else None})
    print(f"results: {out}")
    return 0 if ok and speed_ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
