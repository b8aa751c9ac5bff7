"""Ten monitors against the 100 Hz loop (issue 39): their cost per reading, and the loop's p99.

``--micro``: one reading of a Totem -> Op-safe move held against ten typical monitors
(following errors, velocities, the tool's height and position: every kind of name, the
tool's forward kinematics included), ``--repeat`` times; prints the median cost of one
reading in microseconds and its share of the 10 ms cycle.

Default: ``sequences/opsafe.yaml`` in real time on the simulator, plain and with the ten
monitors on each of its moves, alternating (``--pairs``): the loop's period (spacing of
the ``setpoint`` events) per mode. The goal: the p99 with ten monitors within 0.5 ms of
none.

Run: ``python bench/bench_monitors.py --micro`` and ``python bench/bench_monitors.py
[--pairs 2] [--rt-priority N]``
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from loop_pairs import alternate, periods, row, summary, use_rt_priority  # noqa: E402
from seqrun_runs import RESULTS, ROOT, machine, write_json  # noqa: E402

MONITORS = [
    "abs(following_error_deg[1]) < 4", "abs(following_error_deg[2]) < 4",
    "abs(following_error_deg[4]) < 4", "abs(following_error_deg[6]) < 4",
    "abs(vel_deg_s[1]) < 40", "abs(vel_deg_s[4]) < 40",
    "tool.z_mm > 20", "-900 < tool.x_mm < 900", "tool.y_mm < 1200",
    "sequence_time_s < 600",
]


def micro(repeat: int) -> dict:
    import numpy as np

    from seqrun.arm.description import load_arm
    from seqrun.execution.monitors import Monitors
    from seqrun.steps.params import MonitorSpec

    arm = load_arm(ROOT / "arms" / "lwa3.yaml")
    monitors = Monitors(arm, lambda *a, **k: None)
    monitors.start_step([MonitorSpec.model_validate({"while": m}) for m in MONITORS], 0.0)

    class Reading:
        def __init__(self, t: float, deg: np.ndarray) -> None:
            self.t, self.user_deg, self.short_state = t, deg, {}

    totem = np.zeros(7)
    opsafe = np.array([70.0, 30.0, 0.0, 70.0, 20.0, 50.0, 0.0])
    readings = [Reading(k * 0.01, totem + (opsafe - totem) * k / 500) for k in range(501)]
    costs = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        for r in readings:
            monitors.observe(r, r.user_deg, r.t)
        costs.append((time.perf_counter() - t0) / len(readings))
    us = statistics.median(costs) * 1e6
    return {"monitors": len(MONITORS), "us_per_reading": round(us, 1),
            "share_of_10ms_cycle": round(us / 10_000, 4)}


def monitored_copy(folder: Path) -> Path:
    """A copy of opsafe.yaml (and the files it includes) whose moves carry the monitors."""
    for name in ("opsafe.yaml", "startup.yaml"):
        shutil.copy(ROOT / "sequences" / name, folder / name)
    text = (folder / "opsafe.yaml").read_text(encoding="utf-8")
    specs = ", ".join(f'{{while: "{m}"}}' for m in MONITORS)
    for label in ("Up to Totem (clear of the desk)", "Totem to Op-safe"):
        text = text.replace(f"label: {label}}}", f"label: {label}, monitors: [{specs}]}}")
    assert text.count("monitors:") == 2, "opsafe.yaml changed: update the bench"
    (folder / "opsafe.yaml").write_text(text, encoding="utf-8")
    return folder / "opsafe.yaml"


def one_run(path: Path) -> dict:
    from seqrun.arm.description import load_arm
    from seqrun.clock import RealClock
    from seqrun.sequence.loader import load_sequence
    from seqrun.service.connection import open_connection
    from seqrun.service.runner import run_sequence

    loaded = load_sequence(path)
    arm = load_arm(loaded.arm_path)
    setpoints: list = []

    def record(event) -> None:
        if event.type in ("setpoint", "step_started", "controlled_stop"):
            setpoints.append(event)

    clock = RealClock()
    connection = open_connection(force_sim=True, clock=clock, default_bitrate=arm.can.bitrate)
    cpu0 = time.process_time()
    try:
        outcome = run_sequence(loaded, arm, connection, log_dir=None,
                               confirm=lambda prompt: True, listeners=[record],
                               html_report=False)
    finally:
        connection.close()
    return {"exit_code": outcome.result.exit_code, "periods": periods(setpoints),
            "cpu_s": time.process_time() - cpu0}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--micro", action="store_true")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--pairs", type=int, default=2)
    ap.add_argument("--rt-priority", type=int, default=None)
    args = ap.parse_args()
    if args.micro:
        out = {"machine": machine(), "load": os.getloadavg(), **micro(args.repeat)}
        print(f"{out['monitors']} monitors: {out['us_per_reading']} µs per reading "
              f"({out['share_of_10ms_cycle'] * 100:.2f} % of a 10 ms cycle), "
              f"load {out['load'][0]:.1f}")
        write_json(RESULTS / "monitors-micro.json", out)
        return
    use_rt_priority(args.rt_priority)
    load0 = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        paths = {"none": ROOT / "sequences" / "opsafe.yaml",
                 "ten": monitored_copy(Path(tmp))}
        runs = alternate(args.pairs, ("none", "ten"), lambda mode: one_run(paths[mode]))
    out = {"machine": machine(), "load_before": load0, "load_after": os.getloadavg(),
           "rt_priority": args.rt_priority}
    for mode in ("none", "ten"):
        s = summary(runs[mode], 0.01)
        s["cpu_s_per_run"] = [round(r["cpu_s"], 2) for r in runs[mode]]
        out[f"monitors_{mode}"] = s
        print(f"{row(f'monitors {mode:4s}', s)}  CPU {s['cpu_s_per_run']} s  "
              f"exit {s['exit_codes']}")
    print(f"load average before {load0[0]:.1f}, after {out['load_after'][0]:.1f}")
    write_json(RESULTS / "monitors.json", out)


if __name__ == "__main__":
    main()
