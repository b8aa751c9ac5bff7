"""One run, assembled: bus connection -> the arm's driver -> run folder -> executor.

The CLI (``seqrun run``), the dry run (``seqrun validate``) and the end-to-end tests all go
through :func:`run_sequence`, so what the tests prove is what the operator runs.
"""

from __future__ import annotations

import gc
import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable

from seqrun import __version__
from seqrun.arm.description import ArmDescription
from seqrun.clock import VirtualClock
from seqrun.drivers.base import ArmDriver
from seqrun.drivers.registry import open_driver
from seqrun.events import EventHub
from seqrun.executor import Executor, Listener
from seqrun.runfolder.logfile import write_whole
from seqrun.results import EXIT_FAULT, RunResult, StepResult
from seqrun.sequence.checks import check_from_arm
from seqrun.sequence.loader import LoadedSequence
from seqrun.service.connection import Connection, response_timeout_s
from seqrun.service.heap import keep_large_blocks_out_of_arenas, return_freed_memory
from seqrun.service.host_watch import HostWatch
from seqrun.service.run_control import halt_on_foreign_frames
from seqrun.stop_requests import StopRequests


@dataclass
class RunOutcome:
    result: RunResult
    report: dict | None
    log_dir: Path | None
    executor: Executor
    #: Why report.html could not be written (the run's outcome stands either way).
    report_error: str | None = None


def build_executor(loaded: LoadedSequence, arm: ArmDescription, connection: Connection, *,
                   speed: float = 1.0, command_mode: str | None = None,
                   cycle_hz: float | None = None,
                   confirm: Callable[[str], bool] | None = None,
                   before_step: Callable | None = None,
                   listeners: Iterable[Listener] = (), dry_run: bool = False,
                   confirm_clear_latched: Callable[[str], bool] | None = None,
                   requests: StopRequests | None = None,
                   driver: ArmDriver | None = None, events: EventHub | None = None
                   ) -> tuple[Executor, ArmDriver]:
    """The executor of one run and its driver; ``driver``: the arm session's own (else a
    new one on the connection); ``events``: the hub its events go to (the session's)."""
    if driver is None:
        driver = open_driver(arm, connection,
                             # (a dry run keeps the arm file's: deterministic results)
                             response_timeout_s=(arm.can.response_timeout_s if dry_run
                                                 else response_timeout_s(arm)))
    executor = Executor(driver, arm, connection.clock, sequence_check=check_from_arm,
                        poses_dir=loaded.pose_path or loaded.poses_dir, speed=speed,
                        command_mode=command_mode, cycle_hz=cycle_hz, confirm=confirm,
                        before_step=before_step, listeners=list(listeners), dry_run=dry_run,
                        confirm_clear_latched=confirm_clear_latched, requests=requests,
                        events=events)
    return executor, driver


def run_sequence(loaded: LoadedSequence, arm: ArmDescription, connection: Connection, *,
                 log_dir: Path | None, file: str | None = None, speed: float = 1.0,
                 first_step: int = 1, command_mode: str | None = None,
                 cycle_hz: float | None = None,
                 confirm: Callable[[str], bool] | None = None,
                 before_step: Callable | None = None,
                 listeners: Iterable[Listener] = (), dry_run: bool = False,
                 on_executor: Callable[[Executor], None] | None = None,
                 confirm_clear_latched: Callable[[str], bool] | None = None,
                 meta: dict | None = None,
                 html_report: bool = True,
                 requests: StopRequests | None = None,
                 warn: Callable[[str], None] | None = None,
                 driver: ArmDriver | None = None,
                 events: EventHub | None = None, part: Any = None) -> RunOutcome:
    """Run ``loaded`` on ``connection``; writes the run folder when ``log_dir`` is given,
    with report.html drawn after the run (``html_report``).

    ``on_executor`` is called with the executor before the run starts (displays and tests
    hook in there); ``meta`` goes into report.json (e.g. the zero reference); ``requests``
    is the inbox signal handlers post stop requests to; ``warn`` is told once when writing
    the run folder fails. The connection is not closed. Whichever way the run ends (even
    by an exception), the run folder is finished. ``driver`` (the arm session's) is used
    and left open; otherwise the run's own driver is closed at the end. ``part``: one
    arm's part of a campaign run (:class:`~seqrun.service.arm_part.ArmPart`: the run's
    time base and its face of the run's one run.mcap).
    """
    keep_large_blocks_out_of_arenas()  # run after run, the process keeps one run's memory
    own_driver = driver is None
    executor, driver = build_executor(loaded, arm, connection, speed=speed,
                                      command_mode=command_mode, cycle_hz=cycle_hz,
                                      confirm=confirm, before_step=before_step,
                                      listeners=listeners, dry_run=dry_run,
                                      confirm_clear_latched=confirm_clear_latched,
                                      requests=requests, driver=driver, events=events)
    # Another master's request on the bus halts the run (one controller per bus).
    halt_on_foreign_frames(executor, driver)
    log = None
    if log_dir is not None:
        from seqrun.service.runlog import RunLog  # python-can's log writer: only for a run folder

        mcap = part.mcap if part is not None else _mcap_log(log_dir, loaded, arm, warn)
        ros = {"ros": {"namespace": mcap.names.namespace,
                       "distribution": mcap.distribution}} if mcap is not None else {}
        log = RunLog(log_dir, {"sequence": loaded.name, "file": file or loaded.file,
                               "arm": arm.name, "bus": connection.description,
                               "simulator": connection.is_simulator,
                               "faults": [f.spec for f in connection.faults], "speed": speed,
                               "first_step": first_step, "seqrun": __version__,
                               **(meta or {}), "inputs": _inputs(loaded, arm), **ros,
                               **({"params": dict(loaded.param_values)}
                                  if getattr(loaded, "param_values", None) else {})},
                     clock=connection.clock,
                     channel=getattr(connection.bus, "channel", None) or "can0", warn=warn,
                     mcap=mcap, time_base=part.time_base if part is not None else None)
        driver.add_frame_listener(log.on_frame)
        executor.listeners.insert(0, log.on_event)
        # what a signed confirm signs: these inputs, as validated
        executor.inputs_sha256 = inputs_digest(_inputs(loaded, arm))
    # The host's part in the run: stalls named in a fault's verdict, report.json's "host".
    host = HostWatch(wall_clock=not isinstance(connection.clock, VirtualClock))
    executor.listeners.append(host)
    if on_executor is not None:
        on_executor(executor)
    result = None
    report = None
    try:
        result = host.explain(executor.run(loaded, first_step=first_step))
    except BaseException as exc:
        if log is not None:
            log.finish(executor.interrupted_result or _unfinished(executor, loaded, exc),
                       host=host.summary())
        raise
    finally:
        if log is not None:
            if result is not None:
                report = log.finish(result, host=host.summary())
                if log_dir is not None:
                    add_signatures(log_dir, result, warn)
            log.close()
            if not own_driver:
                driver.remove_frame_listener(log.on_frame)
        if own_driver:
            driver.close()
    report_error = None
    if log is not None and log_dir is not None and html_report:
        report_error = write_html_report(log_dir)
    return RunOutcome(result, report, log_dir, executor, report_error)


def _mcap_log(folder: Path, loaded: LoadedSequence, arm: ArmDescription,
              warn: Callable[[str], None] | None) -> Any:
    """run.mcap's writer (seqrun/service/mcap_log.py), unless the campaign's seqrun.toml
    says ``[ros] mcap = false``; the ROS 2 distribution is the campaign's (default Jazzy)."""
    config = getattr(getattr(loaded, "project", None), "config", None)
    ros = getattr(config, "ros", None)
    if ros is not None and not ros.mcap:
        return None
    from seqrun.service.mcap_log import McapLog, distribution_of

    def said(text: str) -> None:
        if warn is not None:
            warn(f"run log: {text}; the run goes on")

    return McapLog(folder, arm, on_error=said,
                   distribution=distribution_of(getattr(loaded, "project", None)))


def write_html_report(folder: Path) -> str | None:
    """Draw folder/report.html; returns why not instead of raising: the run is over and
    its outcome (and exit code) must not depend on the report.

    matplotlib's figures leave many objects in reference cycles; they are collected here,
    before the session can start its next motion, not by a full collection in that motion's
    control loop. The heap pages the report freed then go back to the system."""
    try:
        from seqrun.report import write_html

        write_html(folder)
        return None
    except Exception as exc:  # noqa: BLE001 - a report bug must not turn into a run failure
        return f"{type(exc).__name__}: {exc}"
    finally:
        gc.collect()
        return_freed_memory()


def inputs_digest(inputs: list[dict[str, str]]) -> str:
    """One sha256 for a run's validated inputs: of the canonical JSON of report.json's
    ``inputs`` (each file's kind, path and sha256), so that any changed byte changes it."""
    canonical = json.dumps(inputs, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(canonical.encode()).hexdigest()


def add_signatures(folder: Path, result: RunResult,
                   warn: Callable[[str], None] | None = None) -> None:
    """The run's signed confirms, added to record.json (``signatures``): who answered, as
    what, when and the inputs they signed. Nothing is added to a run without one."""
    signatures = [{"step": s.number, "text": s.label,
                   **{k: s.detail.get(k) for k in SIGNATURE_KEYS}}
                  for s in result.steps if s.detail.get("signed_by")]
    record_file = Path(folder) / "record.json"
    if not signatures or not record_file.is_file():
        return
    try:
        record = json.loads(record_file.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        if warn is not None:
            warn(f"record.json: signatures not added ({exc})")
        return
    record["signatures"] = signatures
    error = write_whole(record_file, json.dumps(record, indent=2) + "\n")
    if error is not None and warn is not None:
        warn(f"record.json: signatures not added ({error})")


#: What a signed confirm keeps (its step's detail in report.json, record.json's signatures).
SIGNATURE_KEYS = ("signed_by", "signed_role", "signed_at_utc", "inputs_sha256")


def _inputs(loaded: LoadedSequence, arm: ArmDescription) -> list[dict[str, str]]:
    """Every file the run was validated from, with its SHA-256 as it was read: the run
    uses these contents only (poses are frozen at load time, the arm is loaded once)."""
    items = loaded.inputs()
    if arm.sha256:
        items.append({"kind": "arm", "file": arm.source_file, "sha256": arm.sha256})
    return items


def _unfinished(executor: Executor, loaded: LoadedSequence, exc: BaseException) -> RunResult:
    """The result of a run an exception ended outside any step (the executor did not get
    to say): failed, exit 3, whatever it was."""
    steps = [StepResult.planned(s, getattr(s, "title", None) or s.kind, str(s.location))
             for s in loaded.steps]
    message = f"interrupted ({exc!r}) before the run could finish"
    return RunResult("failed", EXIT_FAULT, message, steps, 0.0,
                     executor.elapsed_s(),
                     {"cause": "interrupted", "module": None, "message": message,
                      "step": None, "halt_sent": False, "halt_confirmed": False})
