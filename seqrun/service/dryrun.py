"""The dry run: the real executor against the simulated arm at virtual time.

Nothing here opens a real bus: the connection is always the built-in simulator, on a
:class:`~seqrun.clock.VirtualClock`, started in the given pose. The executor, planner,
client, codec, simulated wire and control-loop rate (``control.cycle_hz``) are the ones a
run uses, so every figure of a dry run (durations, velocities, following error, guard
clearances, the verdict and the failing step, under a rehearsed ``--sim-fault`` too) is
the one ``seqrun run --virtual-time`` reports (tests/test_dryrun_is_the_run.py).
"""

from __future__ import annotations

import gc
import math
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

from seqrun import frozen_objects
from seqrun.arm.description import ArmDescription
from seqrun.clock import VirtualClock
from seqrun.arm.joint_values import LimitValues
from seqrun.drivers.registry import open_driver, simulator_positions
from seqrun.results import RunResult
from seqrun.sequence.loader import LoadedSequence
from seqrun.service.connection import open_connection
from seqrun.service.runner import run_sequence

if TYPE_CHECKING:
    from seqrun.sim.faults import Fault

#: Checks a simulator cannot make for the operator, listed in every dry-run report.
ALWAYS_UNVERIFIED = (
    "collisions beyond the arm file's link volumes and obstacles (its capsule radii are "
    "estimates, not measured housings)",
    "the real modules' tracking and timing (the dry run uses the simulated PRL model)",
)


@dataclass
class DryRun:
    result: RunResult
    start_pose: str
    cycle_hz: float
    wall_s: float
    events: list[dict] = field(default_factory=list, repr=False)
    #: Why the requested report could not be drawn (None: written or not asked for).
    report_error: str | None = None
    #: The simulator faults rehearsed (spec strings, as ``--sim-fault`` takes them).
    faults: list[str] = field(default_factory=list)
    #: Where the simulated arm stood at the end (user degrees by joint; None: never
    #: measured): where the next sequence of a suite starts.
    end_deg: dict[str, float] | None = None

    @property
    def passed(self) -> bool:
        return self.result.exit_code == 0

    @property
    def simulated_s(self) -> float:
        return self.result.duration_s

    @property
    def speedup(self) -> float:
        return self.simulated_s / self.wall_s if self.wall_s > 0 else math.inf

    def as_dict(self) -> dict[str, Any]:
        from seqrun.runfolder.requirements import requirement_results

        r = self.result
        steps = [s.as_dict() for s in r.steps]
        requirements = requirement_results(steps)   # as a run's report.json has them
        return {
            "passed": self.passed, "status": r.status, "message": r.message,
            "start_pose": self.start_pose, "cycle_hz": self.cycle_hz, "faults": self.faults,
            "simulated_s": round(self.simulated_s, 4),
            "planned_motion_s": round(r.planned_duration_s, 4),
            "wall_s": round(self.wall_s, 4), "speedup": round(self.speedup, 1),
            "steps": steps,
            **({"requirements": requirements} if requirements else {}),
            "min_heights_mm": r.min_heights_mm,
            "fault": r.fault,
            "not_verified": list(r.not_verified) + list(ALWAYS_UNVERIFIED),
            **({"errors": r.extra["errors"]} if r.extra.get("errors") else {}),
            **({"blocks": r.extra["blocks"]} if r.extra.get("blocks") else {}),
        }


def prepare_started(connection, arm: ArmDescription) -> None:
    """Bring the simulated modules to 'started' (reset, homed, the arm file's limits
    written), through the arm's driver as a start-up sequence would."""
    driver = open_driver(arm, connection)
    try:
        driver.reset(None)
        driver.home(None)
        driver.write_limits({j.name: LimitValues(*j.limits_deg) for j in arm.joints})
    finally:
        driver.close()


def dry_run(loaded: LoadedSequence, arm: ArmDescription, start_deg: Mapping[str, float], *,
            start_pose: str = "park", started: bool = False, speed: float = 1.0,
            cycle_hz: float | None = None, command_mode: str | None = None,
            time_limit_s: float | None = None,
            report_html: Path | None = None, faults: Sequence[Fault] = ()) -> DryRun:
    """Run ``loaded`` on a simulated arm standing at ``start_deg`` (user degrees).

    ``started``: the simulated modules are reset, homed and limited before the run (for
    sequences written for an arm that is already up). ``time_limit_s`` (default the arm
    file's ``control.max_dry_run_s``): simulated time after which the dry run stops with
    an error, so that no sequence makes validation run for ever. ``report_html``: draw the
    dry run's report there (the run is logged to a temporary run folder for it, which
    costs time). ``cycle_hz``: another loop rate than the arm file's (benchmarks; the
    figures are then not the run's). ``faults``: simulator faults to rehearse, timed from
    the start of the dry run as ``seqrun run --virtual-time --sim-fault`` times them.
    """
    if report_html is not None:
        with tempfile.TemporaryDirectory(prefix="seqrun-dry-run-") as folder:
            run = _dry_run(loaded, arm, start_deg, start_pose=start_pose, started=started,
                           speed=speed, cycle_hz=cycle_hz, command_mode=command_mode,
                           time_limit_s=time_limit_s, log_dir=Path(folder), faults=faults)
            try:
                from seqrun.report import write_html

                write_html(folder, report_html)
            except OSError as exc:
                run.report_error = f"{report_html}: {exc.strerror or exc}"
        return run
    return _dry_run(loaded, arm, start_deg, start_pose=start_pose, started=started,
                    speed=speed, cycle_hz=cycle_hz, command_mode=command_mode,
                    time_limit_s=time_limit_s, faults=faults)


def _dry_run(loaded: LoadedSequence, arm: ArmDescription, start_deg: Mapping[str, float], *,
             start_pose: str, started: bool, speed: float, cycle_hz: float | None,
             command_mode: str | None, time_limit_s: float | None = None,
             log_dir: Path | None = None, faults: Sequence[Fault] = ()) -> DryRun:
    # The objects that exist before the dry run (a validating process: pydantic's models,
    # numpy, the sequence's) are not its garbage: out of the collector's sight while it runs,
    # the collections its own objects cause do not traverse them again. Back in sight
    # afterwards; left alone when the process keeps objects frozen itself (the seqrun
    # program, the console: seqrun.frozen_objects).
    freeze = not frozen_objects.kept()
    if freeze:
        gc.freeze()
    try:
        return _dry_run_unfrozen(loaded, arm, start_deg, start_pose=start_pose,
                                 started=started, speed=speed, cycle_hz=cycle_hz,
                                 command_mode=command_mode, time_limit_s=time_limit_s,
                                 log_dir=log_dir, faults=faults)
    finally:
        if freeze:
            gc.unfreeze()


def _dry_run_unfrozen(loaded: LoadedSequence, arm: ArmDescription,
                      start_deg: Mapping[str, float], *, start_pose: str, started: bool,
                      speed: float, cycle_hz: float | None, command_mode: str | None,
                      time_limit_s: float | None, log_dir: Path | None,
                      faults: Sequence[Fault]) -> DryRun:
    clock = VirtualClock()
    positions = simulator_positions(arm, start_deg)
    connection = open_connection(force_sim=True, clock=clock, sim_positions=positions,
                                 sim_modules=arm.present_module_ids,
                                 faults=list(faults), default_bitrate=arm.can.bitrate,
                                 python_can=False, bus_kwargs=gripper_switches(arm, loaded))
    hz = cycle_hz or arm.control.cycle_hz
    events: list[dict] = []
    try:
        if started:
            prepare_started(connection, arm)
        wall = time.perf_counter()
        outcome = run_sequence(loaded, arm, connection, log_dir=log_dir, speed=speed,
                               cycle_hz=hz, command_mode=command_mode, confirm=None,
                               listeners=[_keep_summary(events)], dry_run=True,
                               on_executor=_bounded(time_limit_s or arm.control.max_dry_run_s),
                               html_report=False)
        wall = time.perf_counter() - wall
        end = _where_it_stands(connection, arm) if outcome.result.exit_code == 0 else None
    finally:
        connection.close()
    return DryRun(outcome.result, start_pose, hz, wall, events,
                  faults=[f.spec for f in faults], end_deg=end)


def gripper_switches(arm: ArmDescription, loaded: LoadedSequence) -> dict[str, object]:
    """The simulator's gripper for an arm file with one: at its module id, with the part
    a run on the built-in simulator has between its jaws too
    (:mod:`seqrun.service.simulated_part`: the campaign's ``[sim] gripper_part_mm``, else
    the sequence's first grip; a ``SEQRUN_SIM_OPTIONS`` part wins, as it does in a run)."""
    from seqrun.service.simulated_part import simulated_part, switch_given

    if arm.gripper is None:
        return {}
    switches: dict[str, object] = {"gripper_module": arm.gripper.module}
    if not switch_given({}):
        part = simulated_part(loaded.steps, loaded.project)
        switches["gripper_part_mm"] = 0.0 if part is None else part.width_mm
    return switches


def _bounded(seconds: float):
    def hook(executor) -> None:
        executor.time_limit_s = seconds
    return hook


def _where_it_stands(connection, arm: ArmDescription) -> dict[str, float]:
    """The simulated arm's joints (user degrees) once the run is over: read through the
    arm's driver, after the run (the run's frames and figures are not touched)."""
    driver = open_driver(arm, connection)
    try:
        return {name: float(deg) for name, deg in zip(arm.joint_names, driver.read().positions_deg)}
    finally:
        driver.close()


def _keep_summary(events: list[dict]):
    """Keep the events a report needs (not the per-cycle ones)."""
    def listener(event) -> None:
        if event.type not in ("setpoint", "measurement"):
            events.append(event.as_dict())
    return listener
