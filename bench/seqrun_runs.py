"""Shared by the benches: one ``seqrun run`` of a shipped sequence on the simulator.

``run_shipped`` does what ``seqrun run sequences/NAME.yaml --sim --yes [--virtual-time]``
does, through the same entry point (:func:`seqrun.service.runner.run_sequence`): a simulator
connection from :func:`seqrun.service.connection.open_connection`, confirmations answered yes,
optionally the run folder. Afterwards it reads the arm once more (not timed) so that the
final joint errors are measured the same way for every contender.
"""

from __future__ import annotations

import json
import os
import platform
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from seqrun.arm.description import ArmDescription, load_arm  # noqa: E402
from seqrun.clock import Clock  # noqa: E402
from seqrun.service.connection import open_connection  # noqa: E402
from seqrun.powercube.client import PowerCubeClient  # noqa: E402
from seqrun.service.runner import RunOutcome, run_sequence  # noqa: E402
from seqrun.sequence.loader import LoadedSequence, load_sequence
from seqrun.drivers.powercube.units import to_user_deg  # noqa: E402

RESULTS = ROOT / "bench" / "results"


def load_shipped(name: str) -> tuple[LoadedSequence, ArmDescription]:
    loaded = load_sequence(ROOT / "sequences" / f"{name}.yaml")
    return loaded, load_arm(loaded.arm_path)


def read_user_deg(bus, clock: Clock, arm: ArmDescription) -> list[float]:
    """Every joint's position in user degrees, read from the arm (one pipelined read)."""
    client = PowerCubeClient(bus, clock, response_timeout=arm.can.response_timeout_s)
    try:
        readings = client.read_arm([j.module for j in arm.joints])
    finally:
        client.close()
    return [to_user_deg(j, r.position) for j, r in zip(arm.joints, readings)]


@dataclass
class SeqrunRun:
    outcome: RunOutcome
    clock_s: float          # seconds on the run's clock (== wall seconds in real time)
    wall_s: float
    final_deg: list[float]
    events: list[dict] = field(default_factory=list, repr=False)

    @property
    def result(self):
        return self.outcome.result


def run_shipped(name: str, clock: Clock, *, log_dir: Path | None = None,
                listeners=(), keep_events: bool = False, cycle_hz: float | None = None,
                connection_hook=None, html_report: bool = True) -> SeqrunRun:
    """``seqrun run sequences/NAME.yaml --sim --yes`` on ``clock``.

    ``connection_hook(connection) -> connection`` may replace the connection handed to the
    runner (the loop bench wraps its clock). ``html_report=False``: no report.html drawn
    after the run (``--no-report``)."""
    loaded, arm = load_shipped(name)
    connection = open_connection(force_sim=True, clock=clock, default_bitrate=arm.can.bitrate)
    events: list[dict] = []
    listeners = list(listeners) + ([events.append] if keep_events else [])
    try:
        used = connection_hook(connection) if connection_hook else connection
        c0, w0 = clock.now(), time.perf_counter()
        outcome = run_sequence(loaded, arm, used, log_dir=log_dir, cycle_hz=cycle_hz,
                               confirm=lambda prompt: True, listeners=listeners,
                               html_report=html_report)
        clock_s, wall_s = clock.now() - c0, time.perf_counter() - w0
        final = read_user_deg(connection.bus, clock, arm)
    finally:
        connection.close()
    return SeqrunRun(outcome, clock_s, wall_s, final, events)


def median(values):
    values = [v for v in values if v is not None]
    return statistics.median(values) if values else None


def machine() -> dict:
    try:
        load = os.getloadavg()
    except OSError:  # pragma: no cover
        load = None
    def git(*args: str) -> str:
        try:
            return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True,
                                  timeout=10, check=False).stdout.rstrip()
        except (OSError, subprocess.SubprocessError):  # pragma: no cover
            return ""

    dirty = [line[3:] for line in git("status", "--porcelain", "--", "seqrun").splitlines()]
    return {"commit": git("rev-parse", "--short", "HEAD").strip() or None,
            "uncommitted_seqrun_files": dirty,
            "cpus": os.cpu_count(), "scheduling": _scheduling(), "python": sys.version.split()[0],
            "platform": platform.platform(), "processor": platform.processor() or None,
            "loadavg_at_start": [round(x, 2) for x in load] if load else None,
            "date": datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")}


def _scheduling() -> str:
    """This process' CPU scheduling (``chrt -f N`` gives SCHED_FIFO)."""
    try:
        policy = os.sched_getscheduler(0)
        names = {os.SCHED_OTHER: "SCHED_OTHER", os.SCHED_FIFO: "SCHED_FIFO",
                 os.SCHED_RR: "SCHED_RR"}
        prio = os.sched_getparam(0).sched_priority
        return f"{names.get(policy, policy)} priority {prio}, nice {os.nice(0)}"
    except (AttributeError, OSError):  # pragma: no cover - not Linux
        return "unknown"


def write_json(path: Path, data: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=2, ensure_ascii=False) + "\n")
