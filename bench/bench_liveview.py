"""The live view against the 100 Hz loop: ``seqrun run`` with the live view vs ``--plain``.

Each run is a whole ``seqrun run sequences/NAME.yaml --yes`` process on the simulator in
real time, inside a pseudo-terminal (pty, 120x40) so that rich really renders the live view
(``--plain`` runs get the same pty). Live and plain runs alternate in pairs (the order
flips every pair) under the same conditions. The loop period is taken from the run folder:

- ``events``: spacing of consecutive ``setpoint`` events within a move (one per cycle;
  their ``t`` is the executor's clock when the cycle's acknowledges were in);
- ``frames``: spacing of the loop's first motion frame of each cycle in ``trace.log``
  (the first TargetVel/FRAMP/FSTEP request after a gap of more than 4 ms).

Reported per mode (all pairs pooled): cycles, p50 / p99 / max period, periods >= 12 ms,
and skipped slots (a period of k x 10 ms skipped k - 1 slots). The goal: the live view's
row matches the plain one's.

``--compare DIR``: a second seqrun checkout (e.g. ``git worktree add /tmp/before main``):
each pair then runs live and plain with this checkout's code and with DIR's, alternating
(the order of the two checkouts flips every pair too); the rows are per checkout.

Run: ``.venv/bin/python bench/bench_liveview.py [--pairs 3] [--sequence opsafe] [--compare DIR]``
"""

from __future__ import annotations

import argparse
import fcntl
import json
import os
import pty
import select
import struct
import subprocess
import sys
import tempfile
import termios
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from seqrun_runs import RESULTS, ROOT, machine, write_json  # noqa: E402

CYCLE_S = 0.010
MOTION_COMMANDS = {0x0B}  # SetMotion (TargetVel, FRAMP, FSTEP all start with it)


def run_in_pty(args: list[str], timeout: float = 600.0, root: Path = ROOT) -> tuple[int, int]:
    """Run ``python -m seqrun ARGS`` (the code of the checkout ``root``) with a pty as its
    terminal; returns (exit code, bytes of output drained)."""
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 120, 0, 0))
    env = {**os.environ, "PYTHONPATH": str(root), "TERM": "xterm-256color",
           "COLUMNS": "120", "LINES": "40"}
    proc = subprocess.Popen([sys.executable, "-m", "seqrun", *args], cwd=root, env=env,
                            stdin=slave, stdout=slave, stderr=slave, close_fds=True,
                            start_new_session=True)
    os.close(slave)
    drained = 0
    deadline = time.monotonic() + timeout
    try:
        while True:  # drain the terminal as a terminal emulator would
            ready, _, _ = select.select([master], [], [], 0.05)
            if ready:
                try:
                    chunk = os.read(master, 65536)
                except OSError:  # EIO: the child closed the pty
                    chunk = b""
                drained += len(chunk)
                if not chunk and proc.poll() is not None:
                    break
            elif proc.poll() is not None:
                break
            if time.monotonic() > deadline:
                proc.kill()
                raise TimeoutError(f"seqrun {' '.join(args)} did not end within {timeout} s")
        return proc.wait(), drained
    finally:
        os.close(master)


def event_periods(folder: Path) -> list[float]:
    periods = []
    prev = None
    for line in (folder / "events.jsonl").read_text().splitlines():
        event = json.loads(line)
        if event["type"] == "setpoint":
            if prev is not None:
                periods.append(event["t"] - prev)
            prev = event["t"]
        elif event["type"] in ("move_planned", "step_finished", "controlled_stop"):
            prev = None  # a new move: its first cycle has no predecessor
    return periods


def frame_periods(folder: Path) -> list[float]:
    import can

    starts = []
    last = None
    for msg in can.LogReader(str(folder / "trace.log")):
        if msg.is_rx or not msg.data or msg.data[0] not in MOTION_COMMANDS:
            continue
        if last is None or msg.timestamp - last > 0.004:
            starts.append(msg.timestamp)
        last = msg.timestamp
    gaps = np.diff(starts) if len(starts) > 1 else np.array([])
    return [float(g) for g in gaps if g < 1.0]  # longer gaps: between moves


def summary(periods: list[float]) -> dict:
    if not periods:
        return {"cycles": 0}
    p = np.array(periods) * 1000
    skipped = int(sum(max(0, round(x / (CYCLE_S * 1000)) - 1) for x in p))
    return {"cycles": len(p), "p50_ms": round(float(np.percentile(p, 50)), 2),
            "p99_ms": round(float(np.percentile(p, 99)), 2), "max_ms": round(float(p.max()), 2),
            "periods_ge_12ms": int((p >= 12).sum()), "skipped_slots": skipped}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--pairs", type=int, default=3)
    parser.add_argument("--sequence", default="opsafe")
    parser.add_argument("--out", type=Path, default=RESULTS / "liveview.json")
    parser.add_argument("--compare", type=Path, metavar="DIR",
                        help="another seqrun checkout, run alternately with this one")
    opts = parser.parse_args()
    info = machine()
    trees = {"": ROOT}
    if opts.compare is not None:
        trees = {"this ": ROOT, "compare ": opts.compare.resolve()}
    runs: dict[str, list[dict]] = {f"{t}{m}": [] for t in trees for m in ("live", "plain")}
    with tempfile.TemporaryDirectory() as tmp:
        for pair in range(opts.pairs):
            order = ("live", "plain") if pair % 2 == 0 else ("plain", "live")
            labels = list(trees) if pair % 2 == 0 else list(trees)[::-1]
            for tree in labels:
                for mode in order:
                    folder = Path(tmp) / f"{tree.strip() or 'run'}-{mode}-{pair}"
                    args = ["run", f"sequences/{opts.sequence}.yaml", "--yes",
                            "--log-dir", str(folder)] + (["--plain"] if mode == "plain" else [])
                    t0 = time.perf_counter()
                    code, drained = run_in_pty(args, root=trees[tree])
                    wall = time.perf_counter() - t0
                    ev, fr = event_periods(folder), frame_periods(folder)
                    runs[f"{tree}{mode}"].append({
                        "pair": pair, "exit_code": code, "wall_s": round(wall, 2),
                        "terminal_bytes": drained, "events": summary(ev),
                        "frames": summary(fr), "_ev": ev, "_fr": fr})
                    print(f"pair {pair} {tree}{mode:5s}: exit {code}, {wall:.1f} s, "
                          f"{drained} bytes to the terminal, "
                          f"events {summary(ev)}", flush=True)
    table = {}
    for mode, items in runs.items():
        table[mode] = {"events": summary([x for r in items for x in r["_ev"]]),
                       "frames": summary([x for r in items for x in r["_fr"]]),
                       "per_run": [{k: v for k, v in r.items() if not k.startswith("_")}
                                   for r in items]}
    print(f"\n{'':14s} {'source':7s} {'cycles':>7s} {'p50 ms':>7s} {'p99 ms':>7s} "
          f"{'max ms':>7s} {'>=12ms':>7s} {'skipped':>8s}")
    for mode in table:
        for source in ("events", "frames"):
            s = table[mode][source]
            print(f"{mode:14s} {source:7s} {s.get('cycles', 0):7d} {s.get('p50_ms', 0):7.2f} "
                  f"{s.get('p99_ms', 0):7.2f} {s.get('max_ms', 0):7.2f} "
                  f"{s.get('periods_ge_12ms', 0):7d} {s.get('skipped_slots', 0):8d}")
    write_json(opts.out, {"machine": info, "sequence": opts.sequence, "pairs": opts.pairs,
                          "compare": str(opts.compare) if opts.compare else None,
                          "loadavg_at_end": [round(x, 2) for x in os.getloadavg()],
                          **table})
    print(f"\nwritten {opts.out}")


if __name__ == "__main__":
    main()
