"""Shared by the loop benchmarks that pair runs with and without something beside the loop
(a slow subscriber, the run.mcap writer, Foxglove live, a second arm): the loop's periods
read from the ``setpoint`` events, their summary, the alternating order of the runs and the
real-time scheduling of ``--rt-priority``.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np


def _field(event: Any, name: str) -> Any:
    """An event's field, whether the event is a dict (a listener's) or a typed event."""
    return event.get(name) if isinstance(event, dict) else getattr(event, name, None)


def periods(events: list) -> list[float]:
    """Spacing (s) of consecutive setpoints of the same step (one per control cycle)."""
    out: list[float] = []
    prev = None
    for e in events:
        kind = _field(e, "type")
        if kind != "setpoint":
            prev = None if kind in ("step_started", "controlled_stop") else prev
            continue
        step, t = _field(e, "step"), _field(e, "t")
        if prev is not None and prev[0] == step:
            out.append(t - prev[1])
        prev = (step, t)
    return out


def summary(runs: list[dict], cycle_s: float = 0.01) -> dict:
    """Every run's periods pooled: p50 / p99 / max, the p99 error from ``cycle_s``, the
    periods of 12 ms or more, and each run's exit code."""
    p = np.array([x for r in runs for x in r["periods"]])
    err = np.abs(p - cycle_s)
    return {"runs": len(runs), "exit_codes": [r["exit_code"] for r in runs],
            "cycles": int(len(p)),
            "p50_ms": round(float(np.percentile(p, 50)) * 1e3, 3),
            "p99_ms": round(float(np.percentile(p, 99)) * 1e3, 3),
            "max_ms": round(float(p.max()) * 1e3, 3),
            "p99_error_ms": round(float(np.percentile(err, 99)) * 1e3, 3),
            "over_12ms": int((p >= 0.012).sum()),
            "dropped_events": sum(r.get("dropped", 0) for r in runs)}


def row(label: str, s: dict) -> str:
    """The summary's figures on one line, the start of every loop benchmark's table row."""
    return (f"{label} cycles {s['cycles']:5d}  p50 {s['p50_ms']:.2f} ms  p99 "
            f"{s['p99_ms']:.2f} ms  max {s['max_ms']:.2f} ms  p99 error "
            f"{s['p99_error_ms']:.2f} ms  >=12 ms {s['over_12ms']}")


def alternate(pairs: int, modes: tuple[str, str],
              one_run: Callable[[str], Any]) -> dict[str, list]:
    """``pairs`` runs of each mode, alternating, the order flipping every pair, so that both
    modes meet the same conditions on a noisy host."""
    runs: dict[str, list] = {mode: [] for mode in modes}
    for k in range(pairs):
        for mode in (modes if k % 2 == 0 else modes[::-1]):
            runs[mode].append(one_run(mode))
    return runs


def use_rt_priority(priority: int | None) -> None:
    """As ``seqrun run --rt-priority N``: this thread (the loop's) at SCHED_FIFO N, threads
    started later at SCHED_RR 1 below it, the interpreter lock handed over often."""
    if priority is None:
        return
    from seqrun.service.realtime import hand_over_the_lock_often, use_fifo, use_round_robin

    use_round_robin()
    use_fifo(priority)
    hand_over_the_lock_often()


def off_on_main(description: str, one_run: Callable[[str, bool], dict], *, label: str,
                key: str, extra: str, extra_unit: str, results: Any, machine: Callable[[], dict],
                write_json: Callable[[Any, dict], None]) -> None:
    """The command line of a benchmark that pairs runs without (``off``) and with (``on``)
    something beside the loop: ``--pairs``, ``--sequence``, ``--rt-priority``; one row per
    mode (``extra``: the per-run field shown and kept beside CPU time), JSON to ``results``
    under ``{key}_{mode}``."""
    import argparse
    import os

    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--pairs", type=int, default=2)
    ap.add_argument("--sequence", default="opsafe")
    ap.add_argument("--rt-priority", type=int, default=None)
    args = ap.parse_args()
    use_rt_priority(args.rt_priority)
    load0 = os.getloadavg()
    runs = alternate(args.pairs, ("off", "on"),
                     lambda mode: one_run(args.sequence, mode == "on"))
    out = {"machine": machine(), "load_before": load0, "load_after": os.getloadavg(),
           "sequence": args.sequence, "rt_priority": args.rt_priority}
    for mode in ("off", "on"):
        s = summary(runs[mode], 0.01)
        s["cpu_s_per_run"] = [round(r["cpu_s"], 2) for r in runs[mode]]
        s[extra] = [r[extra] for r in runs[mode]]
        out[f"{key}_{mode}"] = s
        print(f"{row(f'{label} {mode:3s}', s)}  CPU {s['cpu_s_per_run']} s  "
              f"{extra} {s[extra]}{extra_unit}  exit {s['exit_codes']}")
    print(f"load average before {load0[0]:.1f}, after {out['load_after'][0]:.1f}")
    write_json(results, out)
