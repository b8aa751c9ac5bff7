"""Two arms streaming at 100 Hz, each on its own (simulated) bus: each loop's period with
both arms running vs one arm alone, side by side in one run.

A campaign with arms A and B (examples/two-arms/seqrun.toml: built-in simulator per arm)
runs a two-arm sequence in real time in this process (``seqrun run``'s machinery:
:func:`seqrun.service.arms_run.run_tracks`, one executor and thread per arm): start-up,
then both arms Park -> Totem -> Op-safe -> Totem together. "one" runs arm A's track
alone, "both" runs both tracks; the runs alternate (the order flips every pair). The loop
period is the spacing of consecutive ``setpoint`` events within a move (one per control
cycle), recorded per arm by a synchronous recorder.

Both loops share one Python process (and its GIL) as in ``seqrun run``; the buses are
separate simulated buses. Reported per mode and arm: cycles, p50 / p99 / max period,
p99 period error (|period - 10 ms|), periods >= 12 ms. The goal (issue 28): each arm's
p99 with both running within 2 ms of one arm alone. Say the load: the machine's load
average is recorded (``machine``).

Run: ``python bench/bench_two_arms.py [--pairs 2]``
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from loop_pairs import periods, row, summary  # noqa: E402
from seqrun_runs import RESULTS, ROOT, machine, write_json  # noqa: E402

SEQUENCE = """\
name: Two arms up and over
description: Both arms through Totem to Op-safe and back to Totem, together.
steps:
  - parallel:
      - {arm: A, steps: [include: startup.yaml]}
      - {arm: B, steps: [include: startup.yaml]}
  - parallel:
      - {arm: A, steps: [move: totem, move: opsafe, move: totem]}
      - {arm: B, steps: [move: totem, move: opsafe, move: totem]}
"""


def one_run(folder: Path, arms_wanted: tuple[str, ...]) -> dict:
    from seqrun.sequence.project import open_project
    from seqrun.service.arm_context import resolve_contexts
    from seqrun.service.arms_check import check_arms_sequence
    from seqrun.service.arms_run import run_tracks

    project = open_project(folder)
    check = check_arms_sequence(folder / "sequences" / "bench.yaml", project, dry_run=False)
    assert not check.errors, check.errors
    contexts = {c.arm_id: c for c in resolve_contexts(project=project)}
    tracks = {a: t for a, t in check.tracks.tracks.items() if a in arms_wanted}
    if len(tracks) == 1:  # alone: nobody else signals the order's events
        (arm_id, track), = tracks.items()
        from dataclasses import replace
        steps = tuple(s for s in track.steps if s.kind not in ("signal", "wait_for"))
        steps = tuple(replace(s, number=i + 1) for i, s in enumerate(steps))
        tracks = {arm_id: replace(track, steps=steps)}
    recorded: dict[str, list] = {a: [] for a in tracks}

    def attach(arm_id: str, executor) -> None:
        def record(event, bucket=recorded[arm_id]) -> None:
            if event.type in ("setpoint", "step_started", "controlled_stop"):
                bucket.append(event)
        executor.listeners.append(record)

    connections = {a: contexts[a].open_connection(live=False) for a in tracks}
    try:
        outcome = run_tracks(tracks, {a: contexts[a].arm for a in tracks}, connections,
                             dry_run=False, on_executor=attach, confirm=None,
                             html_report=False)
    finally:
        for c in connections.values():
            c.close()
    for a in tracks:
        if outcome.arms[a].result.exit_code:
            print(f"  arm {a} of {'+'.join(tracks)}: {outcome.arms[a].result.message}")
    return {a: {"exit_code": outcome.arms[a].result.exit_code,
                "periods": periods(recorded[a])} for a in tracks}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=2)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="seqrun-two-arms-") as tmp:
        folder = Path(tmp) / "two-arms"
        shutil.copytree(ROOT / "examples" / "two-arms", folder)
        (folder / "sequences" / "bench.yaml").write_text(SEQUENCE)
        runs: dict[str, list] = {"one A": [], "both A": [], "both B": []}
        for k in range(args.pairs):
            order = (("A",), ("A", "B")) if k % 2 == 0 else (("A", "B"), ("A",))
            for arms in order:
                result = one_run(folder, arms)
                if arms == ("A",):
                    runs["one A"].append(result["A"])
                else:
                    runs["both A"].append(result["A"])
                    runs["both B"].append(result["B"])
    out = {"machine": machine(), **{mode: summary(r) for mode, r in runs.items()}}
    out["p99_both_minus_one_ms"] = {
        arm: round(out[f"both {arm}"]["p99_ms"] - out["one A"]["p99_ms"], 3) for arm in "AB"}
    for mode in runs:
        s = out[mode]
        print(f"{row(f'{mode:7s}', s)}  exit {s['exit_codes']}")
    print(f"p99 both - one: {out['p99_both_minus_one_ms']} ms; "
          f"load {out['machine'].get('loadavg_at_start')}")
    write_json(RESULTS / "two_arms.json", out)


if __name__ == "__main__":
    main()
