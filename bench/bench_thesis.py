"""Park -> Totem -> Op-safe: the thesis' procedure against ``seqrun run``, side by side.

Both drive the same simulated LWA 3 (``seqrun-sim``, exact 1 Mbit/s wire timing), from a
freshly powered-on arm in Park (encoders at 0, not reset, not homed):

- thesis: ``bench/thesis_baseline.py`` replays the thesis' command-line session frame for
  frame - start (read), arm (Reset + MinPos/MaxPos), home (+ read), totem (TargetVel +
  FRAMP for joints 2, 4, 6, + read), opsafe (TargetVel + FRAMP for joints 1, 2, 4, 5, 6,
  + read) - with the launcher's 1-second pause after every CAN message, joint by joint,
  at the thesis' 0.77 rad/s;
- seqrun: ``seqrun run sequences/thesis_procedure.yaml --sim --yes`` through
  ``run_sequence`` (start-up, Park -> Totem -> Op-safe: two synchronized ruckig moves,
  every joint of a move together, each from rest to rest - no blending through
  waypoints - at velocity_scale 0.75, i.e. 22.5 deg/s against the thesis' 44 deg/s;
  each move ends in position; no pause after a move; FK checkpoint), run folder
  written; report.html, which ``seqrun run`` draws once the arm has stopped, is drawn
  after the timed procedure and timed on its own (the thesis has no report). (Until
  2026-11-27 this ran sequences/opsafe.yaml, the facility's sequence: velocity_scale 0.5,
  a settle wait and a 1 s dwell before its check: 3.8x.)

Reported per contender: the time from the first frame to the end of the procedure (the
run's clock: wall time in real time, simulated time with ``--virtual``), CAN frames sent,
and the final joint errors against Op-safe (table 5.2), read from the arm right after
the procedure returned. The ratio is thesis time / seqrun time, per repetition.

Run: ``.venv/bin/python bench/bench_thesis.py [--repeat 3] [--virtual]``
(real time takes about 70 s per repetition: the thesis session alone is 56 s).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from seqrun_runs import (RESULTS, load_shipped, machine, median, read_user_deg,  # noqa: E402
                         run_shipped, write_json)
from thesis_baseline import OPSAFE_DEG, ThesisSession  # noqa: E402

from seqrun.clock import RealClock, VirtualClock  # noqa: E402
from seqrun.service.runner import write_html_report  # noqa: E402
from seqrun.sim.bus import SimBus  # noqa: E402

#: The sequence timed against the thesis (sequences/thesis_procedure.yaml).
SEQUENCE = "thesis_procedure"


def errors(final_deg: list[float]) -> list[float]:
    return [round(f - t, 7) for f, t in zip(final_deg, OPSAFE_DEG)]


def run_thesis(clock, channel: str) -> dict:
    _, arm = load_shipped(SEQUENCE)
    bus = SimBus(channel, clock=clock, bitrate=arm.can.bitrate)
    try:
        session = ThesisSession(bus, clock, arm)
        c0, w0 = clock.now(), time.perf_counter()
        session.park_to_opsafe()
        clock_s, wall_s = clock.now() - c0, time.perf_counter() - w0
        final = read_user_deg(bus, clock, arm)
    finally:
        bus.shutdown()
    err = errors(final)
    return {"time_s": round(clock_s, 3), "wall_s": round(wall_s, 3),
            "frames_sent": len(session.log),
            "final_error_deg": err, "max_abs_error_deg": max(abs(e) for e in err)}


def run_seqrun(clock, log_root: Path, index: int) -> dict:
    folder = log_root / f"seqrun-{index}"
    run = run_shipped(SEQUENCE, clock, log_dir=folder, html_report=False)
    w0 = time.perf_counter()
    report_error = write_html_report(folder)
    report_html_s = time.perf_counter() - w0
    if report_error is not None:
        raise SystemExit(f"report.html: {report_error}")
    result = run.result
    stats = run.outcome.executor.client.stats
    err = errors(run.final_deg)
    return {"time_s": round(run.clock_s, 3), "wall_s": round(run.wall_s, 3),
            "status": result.status, "report_duration_s": round(result.duration_s, 3),
            "report_html_wall_s": round(report_html_s, 3),
            "planned_motion_s": round(result.planned_duration_s, 3),
            "frames_sent": stats.frames_sent,
            "final_error_deg": err, "max_abs_error_deg": max(abs(e) for e in err)}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=1, help="repetitions (median reported)")
    parser.add_argument("--virtual", action="store_true",
                        help="virtual time: a quick check, seconds are simulated")
    parser.add_argument("--out", type=Path, default=None,
                        help="JSON file (default bench/results/thesis.json, "
                             "thesis_virtual.json with --virtual)")
    args = parser.parse_args()
    out = args.out or RESULTS / ("thesis_virtual.json" if args.virtual else "thesis.json")
    info = machine()
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-thesis-") as tmp:
        for i in range(args.repeat):
            clock_a = VirtualClock() if args.virtual else RealClock()
            thesis = run_thesis(clock_a, f"bench-thesis-{i}")
            clock_b = VirtualClock() if args.virtual else RealClock()
            seqrun = run_seqrun(clock_b, Path(tmp), i)
            ratio = thesis["time_s"] / seqrun["time_s"]
            rows.append({"thesis": thesis, "seqrun": seqrun, "ratio": round(ratio, 2)})
            print(f"  repetition {i + 1}/{args.repeat}: thesis {thesis['time_s']:.2f} s, "
                  f"seqrun {seqrun['time_s']:.2f} s ({seqrun['status']}), "
                  f"ratio {ratio:.2f}", flush=True)

    kind = "virtual time (simulated seconds)" if args.virtual else "real time (wall seconds)"
    med = {who: {k: median([r[who][k] for r in rows]) for k in ("time_s", "wall_s",
                                                                 "max_abs_error_deg")}
           for who in ("thesis", "seqrun")}
    ratio = median([r["ratio"] for r in rows])
    last = rows[-1]
    print(f"\nPark -> Totem -> Op-safe on the simulated LWA 3, {kind}, "
          f"median of {args.repeat}")
    header = (f"{'procedure':<50}{'time s':>9}{'wall s':>9}{'frames':>8}{'max |err| deg':>15}"
              f"   final error vs Op-safe j1..j7 [deg]")
    print(header)
    print("-" * len(header))
    for who, label in (("thesis", "thesis (1 s after every message, joint by joint)"),
                       ("seqrun", f"seqrun run sequences/{SEQUENCE}.yaml")):
        e = last[who]["final_error_deg"]
        print(f"{label:<50}{med[who]['time_s']:>9.2f}{med[who]['wall_s']:>9.2f}"
              f"{last[who]['frames_sent']:>8}{med[who]['max_abs_error_deg']:>15.1e}   "
              + " ".join(f"{x:+.0e}" for x in e))
    print(f"\nratio thesis / seqrun: {ratio:.2f}x  (per repetition: "
          f"{', '.join(str(r['ratio']) for r in rows)})")
    if not args.virtual:
        print("wall seconds of the process equal the clock in real time; "
              f"seqrun run report: duration {last['seqrun']['report_duration_s']} s, "
              f"planned motion {last['seqrun']['planned_motion_s']} s; report.html drawn "
              f"after the run in {median([r['seqrun']['report_html_wall_s'] for r in rows]):.2f} s "
              "(median, not in the time above)")
    write_json(out, {"benchmark": "bench_thesis", "clock": "virtual" if args.virtual else "real",
                     "repeat": args.repeat, "machine": info,
                     "command": "python bench/bench_thesis.py " + " ".join(sys.argv[1:]),
                     "median": {**med, "ratio": ratio}, "runs": rows})
    print(f"results: {out}")
    return 0 if all(r["seqrun"]["status"] == "passed" for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
