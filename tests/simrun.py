"""A sequence run in process at virtual time on a fresh simulated arm (powered on at Park),
the way the end-to-end tests run one: validation, executor, run folder, all real."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

from projecttree import ROOT
from seqrun.arm.description import load_arm
from seqrun.clock import VirtualClock
from seqrun.service.connection import Connection, open_connection
from seqrun.service.dryrun import prepare_started
from seqrun.service.runner import RunOutcome, run_sequence
from seqrun.sequence.loader import load_sequence
from seqrun.sim.arm import SimArm
from seqrun.sim.faults import parse_fault_spec


class SimRun(NamedTuple):
    outcome: RunOutcome
    sim: SimArm              # the simulated arm, as the run left it
    connection: Connection   # closed


def run_on_sim(name: str, tmp_path: Path, *, root: Path = ROOT, faults: Iterable[str] = (),
               positions: Mapping[int, float] | Sequence[float] | None = None, started: bool = False,
               before: Callable[[Connection], None] | None = None, html_report: bool = False,
               **kwargs: Any) -> SimRun:
    """Run ``root/sequences/<name>.yaml`` (the arm its sequence names) into ``tmp_path/run``.

    ``faults``: ``--sim-fault`` specs; ``positions``: the modules' power-on positions;
    ``started``: the modules are reset, homed and limited first; ``before(connection)``
    runs before the sequence; ``html_report``: draw report.html too (drawn after the run,
    it costs as much CPU as the run itself, so only tests that read it ask for it); other
    keywords go to :func:`seqrun.service.runner.run_sequence` (``confirm`` answers yes unless
    given)."""
    loaded = load_sequence(root / "sequences" / f"{name}.yaml")
    arm = load_arm(loaded.arm_path)
    connection = open_connection(force_sim=True, clock=VirtualClock(),
                                 faults=[parse_fault_spec(f) for f in faults],
                                 sim_positions=positions)
    try:
        if started:
            prepare_started(connection, arm)
        if before is not None:
            before(connection)
        kwargs.setdefault("confirm", lambda prompt: True)
        outcome = run_sequence(loaded, arm, connection, log_dir=tmp_path / "run",
                               html_report=html_report, **kwargs)
        return SimRun(outcome, connection.bus.arm, connection)
    finally:
        connection.close()
