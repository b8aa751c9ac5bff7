"""The run folder: everything a run leaves behind, written as the run goes.

``runs/<time>-<name>/``
  trace.log.gz  every CAN frame sent and received, candump format, gzip-compressed
                (``can.LogReader`` reads it, so do ``zcat``/``zgrep``; ``zcat trace.log.gz |
                canplayer`` replays it), wall-clock (epoch) time stamps, the bus channel's
                name in both directions. Runs of older versions wrote ``trace.log``
                (uncompressed); every reader here takes both.
  events.jsonl.gz  one executor event per JSON line, gzip-compressed (``zcat
                events.jsonl.gz | jq``; the 100 Hz readings made events.jsonl ~97 MB per
                hour of motion, 6-7x less compressed); ``run_started`` carries
                ``start_epoch_s``, the wall-clock time of the run's t = 0 (an event at ``t``
                happened at ``start_epoch_s + t``, the trace's time base). Runs of older
                versions wrote ``events.jsonl`` (plain); every reader here takes both
                (:func:`seqrun.runfolder.names.events_path`).
  steps.jsonl   one line per finished step (appended: constant cost per step)
  report.json   status, exit code, timing, per-step results, fault. While the run goes it
                says ``running`` and is rewritten at most once a second (it points to
                steps.jsonl); at the end it is written whole. :func:`read_report` assembles
                the report of a run that was killed from what is on disk.
  junit.xml     one test case per step and one per checkpoint (valid against Jenkins
                xunit's junit-10.xsd; junit.ctrf.json: the same in CTRF), measured values as
                the suite's properties (stepNN.<value>), for CI dashboards
  report.html   drawn after the run from the files above (seqrun/report/)
  run.mcap      the run as a ROS 2 bag (MCAP): joint states and commands, /tf, plans,
                events, markers (seqrun/service/mcap_log.py, docs/ros2.md); written by a
                thread of its own from the events this log hands it

Every line of the plain JSON files goes to disk as it is written (one write per line): a
run killed with SIGKILL leaves a readable folder. The compressed files (the trace, the
events) are made decodable on disk at every event other than a cycle's reading (step
boundaries, faults, questions, the end: each of those is on disk before the loop goes on)
and at least every :data:`TRACE_FLUSH_S` of the run's clock: a run killed mid-move loses at
most that much of its readings and frames. A failing disk never disturbs the
run: the first error stops that file, is reported once (``warn``, an event, the report)
and leaves whole lines only.
"""

from __future__ import annotations

import copy
import datetime as _dt
import io
import json
import time
from pathlib import Path
from typing import Any, Callable, TextIO, cast
from xml.sax.saxutils import escape, quoteattr

import can

from seqrun.events import Event, event_line
from seqrun.results import RunResult, StepResult
from seqrun.runfolder.logfile import (GzipLineFile, LineFile, overwrite_in_place, read_lines,
                                      write_whole)
from seqrun.runfolder.names import (EVENTS_NAME, EVENTS_NAMES, TRACE_NAME, TRACE_NAMES,
                                    events_path, trace_path)
from seqrun.runfolder.requirements import requirement_results
from seqrun.service.time_base import TimeBase

#: The running report.json is rewritten at most this often (seconds of real time).
REPORT_INTERVAL_S = 1.0

#: The running report.json is padded to this size: the room its ending takes when the
#: disk is full by then (the short ending below fits in it).
REPORT_RESERVE_BYTES = 4096

#: What the ending of a run says when the disk has room for no more (report.json).
_ENDING_KEYS = ("sequence", "file", "start", "end", "status", "exit_code", "message",
                "duration_s", "planned_duration_s")

#: The trace's lines are made decodable on disk at least this often (run clock, s).
TRACE_FLUSH_S = 0.1
#: Events that are a cycle's reading (the trace is not flushed for them).
_READINGS = ("setpoint", "measurement")

#: Files whose presence says a folder holds a run.
RUN_FILES = ("report.json", *EVENTS_NAMES, *TRACE_NAMES)


def default_run_dir(sequence_name: str, root: Path = Path("runs")) -> Path:
    stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    safe = "".join(c if c.isalnum() or c in "-_" else "-" for c in sequence_name)[:60]
    return root / f"{stamp}-{safe}"


def holds_run(folder: Path) -> bool:
    return any((Path(folder) / name).exists() for name in RUN_FILES)


def prepare_run_folder(log_dir: Path | None, sequence_name: str,
                       root: Path = Path("runs")) -> Path:
    """The folder this run writes, created and checked writable (OSError otherwise).

    Without ``log_dir``: ``<root>/<time>-<name>/``. A ``log_dir`` that already holds a run
    is never overwritten: the run goes to a new ``<time>-<name>/`` folder inside it. Two
    runs in the same second get ``-2``, ``-3`` ... suffixes.
    """
    if log_dir is not None and not holds_run(log_dir):
        folder = Path(log_dir)
        folder.mkdir(parents=True, exist_ok=True)
    else:
        base = default_run_dir(sequence_name, Path(log_dir) if log_dir else Path(root))
        base.parent.mkdir(parents=True, exist_ok=True)
        folder = base
        for n in range(2, 1000):
            try:
                folder.mkdir()
                break
            except FileExistsError:
                folder = base.with_name(f"{base.name}-{n}")
    probe = folder / ".seqrun-write-test"
    probe.write_bytes(b"")
    probe.unlink()
    return folder


def _now_iso() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="milliseconds")


def _iso(epoch: float) -> str:
    return _dt.datetime.fromtimestamp(epoch, _dt.timezone.utc).isoformat(timespec="milliseconds")


class _TraceSink:
    """File object for python-can's candump writer: one line per write, to the trace."""

    def __init__(self, file: GzipLineFile) -> None:
        self._file = file

    def write(self, text: str) -> int:
        self._file.write(text)
        return len(text)

    def flush(self) -> None:
        pass

    def close(self) -> None:
        self._file.close()


class RunLog:
    """Event listener and frame listener writing one run folder.

    :param clock: the run's clock; frame stamps (its readings) become wall-clock time.
    :param channel: the bus channel's name, written on every trace line.
    :param warn: told once, in one line, when writing the run folder fails.
    :param time_base: the run clock's mapping to wall-clock time (default: taken now);
        the arms of a campaign run share one.
    """

    def __init__(self, folder: Path, meta: dict[str, Any], *, clock=None,
                 channel: str | None = None, warn: Callable[[str], None] | None = None,
                 mcap: Any = None, time_base: TimeBase | None = None) -> None:
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.meta = dict(meta)
        self.warn = warn
        self.errors: list[str] = []
        self._failed_files: set[str] = set()
        self.started_iso = _now_iso()
        # One time base: a reading c of the run's clock happened at epoch0 + (c - clock0)
        # (seqrun/service/time_base.py); ``time_base``: a campaign's, shared by its arms.
        if time_base is None and clock is not None:
            time_base = TimeBase.of(clock)
        self._epoch0 = time_base.epoch_s if time_base is not None else time.time()
        self._clock0 = time_base.clock_s if time_base is not None else None
        self.time_base: dict[str, Any] = {}
        self.channel = str(channel) if channel is not None else "can0"
        self._events = GzipLineFile(self.folder / EVENTS_NAME, self._failed)
        self._events_flushed = -float("inf")   # event time of the events' last flush
        self._steps_file = LineFile(self.folder / "steps.jsonl", self._failed)
        self._trace_file = GzipLineFile(self.folder / TRACE_NAME, self._failed)
        self._trace_flushed = -float("inf")   # run clock of the trace's last flush
        self._trace = can.CanutilsLogWriter(cast(TextIO, _TraceSink(self._trace_file)),
                                            channel=self.channel)
        self._closed = False
        self._started: dict[int, dict] = {}
        self._steps_done = 0
        self._last_step: int | None = None
        self._report_written = -1e9
        self._joint_names: list[str] = []
        #: run.mcap's writer (seqrun.service.mcap_log.McapLog): fed every event, never waited on.
        self.mcap = mcap
        self._write_running()

    # Failures ----------------------------------------------------------------------
    def _failed(self, path: Path, exc: OSError) -> None:
        if path.name in self._failed_files:   # said once per file
            return
        self._failed_files.add(path.name)
        text = f"writing {path} failed ({exc.strerror or exc}); that file stops here"
        self.errors.append(text)
        if len(self.errors) == 1 and self.warn is not None:
            try:
                self.warn(f"run log: {text}; the run goes on")
            except Exception:  # noqa: BLE001 - a broken terminal must not stop the run
                pass
        if path != self._events.path:
            self._events.write(event_line({"t": None, "type": "log_failed", "file": path.name,
                                           "error": str(exc)}) + "\n")
            self._events.flush()

    # Listeners -------------------------------------------------------------------
    def on_event(self, event: Event | dict) -> None:
        """Synchronous recorder of a typed event (or its dict): one line on disk before the
        control loop goes on, so a run killed the next instant leaves a complete log."""
        if self._closed:
            return
        if isinstance(event, Event):
            event = event.as_dict()
        kind = event["type"]
        if kind == "run_started" and self._clock0 is not None and "clock_s" in event:
            start = self._epoch0 + (event["clock_s"] - self._clock0)
            self.time_base = {"start_epoch_s": round(start, 6), "start_utc": _iso(start),
                              "clock_s": event["clock_s"]}
            event = {**event, **self.time_base}
        if kind == "run_started":   # names for the per-joint JUnit properties
            self._joint_names = [j.get("name", "") for j in
                                 (event.get("arm") or {}).get("joints", [])]
        self._events.write(event_line(event) + "\n")
        if kind not in _READINGS:   # on disk before the loop goes on
            self._events.flush()
        else:
            t = event.get("t")
            if isinstance(t, (int, float)) and not t - self._events_flushed < TRACE_FLUSH_S:
                self._events_flushed = t
                self._events.flush()
        if self.mcap is not None:
            self.mcap.put(event)
        if kind not in _READINGS:   # what led up to a step boundary, fault or question
            self._trace_file.flush()
        if kind == "step_started":
            self._started[event.get("step", 0)] = event
        elif kind == "step_finished":
            number = event.get("step", 0)
            begun = self._started.pop(number, {})
            line = {"number": number, "kind": begun.get("kind"), "label": begun.get("label"),
                    "location": begun.get("location"),
                    **{k: v for k, v in event.items() if k not in ("type", "step")}}
            self._steps_file.write(event_line(line) + "\n")
            self._steps_done += 1
            self._last_step = number
            if time.monotonic() - self._report_written >= REPORT_INTERVAL_S:
                self._write_running()

    def on_frame(self, msg: can.Message) -> None:
        if self._closed or not self._trace_file.ok:
            return
        line = copy.copy(msg)
        line.channel = self.channel
        if self._clock0 is not None:
            line.timestamp = self._epoch0 + (msg.timestamp - self._clock0)
        self._trace.on_message_received(line)
        if msg.timestamp - self._trace_flushed >= TRACE_FLUSH_S:
            self._trace_flushed = msg.timestamp
            self._trace_file.flush()

    # Final report -----------------------------------------------------------------
    def finish(self, result: RunResult, *, host: dict[str, Any] | None = None) -> dict:
        """Write the final report.json and junit.xml; never raises (errors are recorded).
        ``host``: what the computer did to the run (seqrun/service/host_watch.py)."""
        self._close_mcap()
        steps = [s.as_dict() for s in result.steps]
        report: dict[str, Any] = {
            "status": result.status,
            "exit_code": result.exit_code,
            "message": result.message,
            "duration_s": round(result.duration_s, 4),
            "planned_duration_s": round(result.planned_duration_s, 4),
            "fault": result.fault,
            "latched_at_start": result.latched_at_start,
            "steps": steps,
            "checkpoints": [_checkpoint(s) for s in result.steps if s.kind == "checkpoint"
                            and s.status != "skipped"],
            "not_verified": result.not_verified,
            "min_heights_mm": result.min_heights_mm,
        }
        requirements = requirement_results(steps)
        if requirements:   # only when a step verifies one: other reports stay as they were
            report["requirements"] = requirements
        if result.extra.get("blocks"):   # how each block ended (passed, rescued, failed)
            report["blocks"] = result.extra["blocks"]
        if host is not None:
            report["host"] = host
        junit = junit_xml(self.meta.get("sequence", "sequence"), result, self._joint_names)
        error = write_whole(self.folder / "junit.xml", junit)
        if error is not None:
            self._failed(self.folder / "junit.xml", error)
        self._write_ctrf(result)
        return self._write_report(report, ended=True)

    def _write_ctrf(self, result: RunResult) -> None:
        """``junit.ctrf.json`` beside junit.xml: the same tests in CTRF's JSON."""
        from seqrun.runfolder.ctrf import ctrf_path

        stop = time.time()
        start = float(self.time_base.get("start_epoch_s", stop - result.duration_s))
        path = ctrf_path(self.folder / "junit.xml")
        text = ctrf_json(self.meta.get("sequence", "sequence"), result, self._joint_names,
                         start, stop)
        error = write_whole(path, text)
        if error is not None:
            self._failed(path, error)

    def _write_running(self) -> None:
        self._report_written = time.monotonic()
        self._write_report({"status": "running", "exit_code": None,
                            "steps_file": "steps.jsonl", "steps_finished": self._steps_done,
                            "last_step_finished": self._last_step})

    def _write_report(self, body: dict, ended: bool = False) -> dict:
        report = {"sequence": self.meta.get("sequence"), "file": self.meta.get("file"),
                  "start": self.started_iso, "end": _now_iso() if ended else None,
                  **self.time_base,
                  **{k: v for k, v in self.meta.items() if k not in ("sequence", "file")},
                  **body}
        if ended and self.errors:
            report["log_errors"] = list(self.errors)
        text = json.dumps(report, indent=2, default=str)
        if not ended:  # room kept on disk for the final report, whatever fills the disk
            text = text.ljust(REPORT_RESERVE_BYTES - 1) + "\n"
        error = write_whole(self.folder / "report.json", text)
        if error is not None and ended:
            # The disk is full: the ending in the room the running report holds, so that
            # report.json never says "running" of a run that ended.
            self.errors.append(f"writing {self.folder / 'report.json'} failed "
                               f"({error.strerror or error}); it holds the result only")
            short = {k: report.get(k) for k in _ENDING_KEYS if k in report}
            short["message"] = str(short.get("message"))[:1000]
            short["log_errors"] = [e[:500] for e in self.errors[:3]]
            if overwrite_in_place(self.folder / "report.json",
                                  json.dumps(short, default=str)) is None:
                error = None
        if error is not None:
            self._failed(self.folder / "report.json", error)
        return report

    def _close_mcap(self) -> None:
        """End run.mcap (its thread writes what is queued); its trouble goes to the report."""
        if self.mcap is None:
            return
        mcap, self.mcap = self.mcap, None
        mcap.close()
        if mcap.dropped:
            self.errors.append(f"run.mcap: {mcap.dropped} events were dropped (its writer "
                               "fell behind); seqrun report RUN_DIR --mcap writes it whole")
        if mcap.error:
            self.errors.append(mcap.error)

    def close(self) -> None:
        if self._closed:
            return
        self._close_mcap()
        self._closed = True
        self._events.close()
        self._steps_file.close()
        self._trace_file.close()


def read_report(folder: Path) -> dict:
    """The run's report as far as the folder tells it: report.json of a finished run, or,
    for a run that was killed (``running``), that report with the steps of steps.jsonl
    and the last fault and event of events.jsonl. Partial last lines are ignored."""
    folder = Path(folder)
    report = json.loads((folder / "report.json").read_text(encoding="utf-8"))
    if report.get("status") != "running":
        return report
    report["steps"] = _json_lines(folder / report.get("steps_file", "steps.jsonl"))
    events = read_events(folder)
    faults = [e for e in events if e.get("type") == "fault"]
    if faults:
        report["fault"] = {k: v for k, v in faults[-1].items() if k not in ("t", "type")}
    if events:
        report["last_event"] = events[-1]
    return report


def trace_text(folder: Path) -> str:
    """The trace's candump lines (compressed or not; a trace cut short by a killed run:
    its whole lines)."""
    path = trace_path(folder)
    return b"".join(read_lines(path)).decode("utf-8") if path is not None else ""


def read_trace(folder: Path, *, run_clock: bool = False) -> list[can.Message]:
    """The frames of the trace (trace.log.gz, or an older run's trace.log; a trace cut
    short: its whole lines). With ``run_clock`` their stamps are readings of the run's
    clock (as the executor and the simulator saw them) instead of wall-clock time, to the
    microsecond the trace keeps: ``stamp - start_epoch_s + clock_s`` (from events.jsonl)."""
    folder = Path(folder)
    frames = list(can.CanutilsLogReader(io.StringIO(trace_text(folder))))
    if run_clock:
        started = next(e for e in read_events(folder)
                       if e.get("type") == "run_started")
        shift = started["clock_s"] - started["start_epoch_s"]
        for msg in frames:
            msg.timestamp = round(msg.timestamp + shift, 6)
    return frames


def read_events(folder: Path) -> list[dict]:
    """The run folder's events (events.jsonl.gz, or an older run's events.jsonl), in
    order, up to the first line that does not parse (a run killed mid-line)."""
    path = events_path(folder)
    if path is None:
        return []
    out = []
    for line in read_lines(path):
        try:
            out.append(json.loads(line))
        except json.JSONDecodeError:
            break
    return out


def _json_lines(path: Path) -> list[dict]:
    if not path.exists():
        return []
    out = []
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            out.append(json.loads(line))
        except json.JSONDecodeError:
            break
    return out


def _checkpoint(step: StepResult) -> dict:
    keys = ("expected_position_mm", "reached_position_mm", "position_error_mm",
            "angle_error_deg", "position_tolerance_mm", "angle_tolerance_deg")
    return {"step": step.number, "status": step.status,
            **{k: step.detail[k] for k in keys if k in step.detail}}


#: Step results that become JUnit properties (lists: one property per joint).
_JUNIT_PROPERTIES = ("planned_duration_s", "executed_duration_s", "duration_ratio",
                     "max_following_error_deg", "final_error_deg",
                     "peak_measured_velocity_deg_s", "peak_velocity_deg_s",
                     "velocity_limit_deg_s", "waited_s")
_CHECKPOINT_PROPERTIES = ("expected_position_mm", "reached_position_mm", "reached_rpy_deg",
                          "position_error_mm", "position_tolerance_mm", "angle_error_deg",
                          "angle_tolerance_deg")


def junit_xml(suite: str, result: RunResult, joint_names: list[str] | None = None) -> str:
    """Two suites: one test case per step, one per checkpoint; measured values are
    properties (per joint: ``max_following_error_deg.j2``), so a CI dashboard shows them."""
    names = joint_names or []
    checkpoints = [s for s in result.steps if s.kind == "checkpoint"]
    lines = ['<?xml version="1.0" encoding="UTF-8"?>', "<testsuites>"]
    lines += _junit_suite(suite, suite, result, result.steps, _JUNIT_PROPERTIES, names)
    if checkpoints:
        lines += _junit_suite(f"{suite}: checkpoints", f"{suite}.checkpoints", result,
                              checkpoints, _CHECKPOINT_PROPERTIES, names, checkpoint=True)
    lines.append("</testsuites>")
    return "\n".join(lines) + "\n"


def junit_testsuite(name: str, result: RunResult,
                    joint_names: list[str] | None = None) -> list[str]:
    """The lines of one ``<testsuite>`` of a run's steps, as junit.xml's first one: what a
    test suite's junit.xml holds per sequence run (seqrun/service/suites.py)."""
    return _junit_suite(name, name, result, result.steps, _JUNIT_PROPERTIES,
                        joint_names or [])


def _junit_suite(name: str, classname: str, result: RunResult, steps: list[StepResult],
                 keys: tuple[str, ...], joint_names: list[str], *,
                 checkpoint: bool = False) -> list[str]:
    """One ``<testsuite>`` valid against Jenkins xunit's junit-10.xsd (what strict CI tools
    check): ``errors`` given, the measured values as the suite's properties (a test case
    may have none there), named ``stepNN.<value>``, each step's place in ``<system-out>``
    (a test case has no ``file`` attribute there)."""
    failures = sum(1 for s in steps if s.status in ("failed", "aborted"))
    skipped = sum(1 for s in steps if s.status in ("skipped", "pending"))
    time = sum(s.duration_s or 0.0 for s in steps) if checkpoint else result.duration_s
    lines = [f'<testsuite name={quoteattr(name)} tests="{len(steps)}" '
             f'failures="{failures}" errors="0" skipped="{skipped}" time="{max(time, 0.0):.3f}">']
    properties = [(f"step{s.number:02d}.{key}", value) for s in steps
                  for key, value in [*_junit_properties(s, keys, joint_names),
                                     *_junit_marks(s)]]
    if properties:
        lines.append("  <properties>")
        lines += [f"    <property name={quoteattr(k)} value={quoteattr(v)}/>"
                  for k, v in properties]
        lines.append("  </properties>")
    for s in steps:
        duration = f"{s.duration_s:.3f}" if s.duration_s is not None else "0"
        lines.append(f'  <testcase classname={quoteattr(classname)} '
                     f'name={quoteattr(step_title(s, checkpoint=checkpoint))} time="{duration}">')
        if s.status in ("failed", "aborted"):
            msg = _step_message(s, result)
            lines.append(f'    <failure message={quoteattr(str(msg))}>{escape(str(msg))}</failure>')
        elif s.status in ("skipped", "pending"):
            lines.append('    <skipped message="not run"/>')
        if s.location:
            lines.append(f"    <system-out>{escape(f'step at {s.location}')}</system-out>")
        lines.append("  </testcase>")
    lines.append("</testsuite>")
    return lines


def step_title(step: StepResult, *, checkpoint: bool = False) -> str:
    """A step's test name: its number and what it does."""
    # A step without a label is described starting with its kind ("confirm: …",
    # "move to pose …"): no second kind in front of it.
    kind = "" if step.label.split(":")[0].split(" ")[0] == step.kind else f"{step.kind}: "
    return f"{step.number:02d} {step.label}" if checkpoint else \
        f"{step.number:02d} {kind}{step.label}"


def _step_message(step: StepResult, result: RunResult) -> str:
    return str(step.detail.get("error") or result.message)


def ctrf_json(suite: str, result: RunResult, joint_names: list[str] | None,
              start_s: float, stop_s: float) -> str:
    """The run's CTRF report (seqrun/runfolder/ctrf.py): a test per step, as junit.xml's,
    its measured values in ``extra``."""
    from seqrun import __version__
    from seqrun.runfolder.ctrf import ctrf_report, ctrf_test

    names = joint_names or []
    tests = []
    for s in result.steps:
        keys = _CHECKPOINT_PROPERTIES if s.kind == "checkpoint" else _JUNIT_PROPERTIES
        values: dict[str, Any] = dict(_junit_properties(s, keys, names))
        values.update({k: v for k, v in (("verifies", s.verifies), ("tags", s.tags)) if v})
        failed = s.status in ("failed", "aborted")
        tests.append(ctrf_test(step_title(s), s.status, s.duration_s, suite=suite,
                               message=_step_message(s, result) if failed else None,
                               location=s.location,
                               extra={"kind": s.kind, **values} if values else
                               {"kind": s.kind}))
    return ctrf_report(tests, start_s=start_s, stop_s=stop_s, version=__version__,
                       extra={"status": result.status, "exit_code": result.exit_code})


def _junit_marks(step: StepResult) -> list[tuple[str, str]]:
    """``verifies`` and ``tags`` of a step as properties (ids joined by spaces)."""
    return [(key, " ".join(ids)) for key, ids in (("verifies", step.verifies),
                                                  ("tags", step.tags)) if ids]


def _junit_properties(step: StepResult, keys: tuple[str, ...],
                      joint_names: list[str]) -> list[tuple[str, str]]:
    values = {**step.detail, "planned_duration_s": step.planned_duration_s}
    out = []
    for key in keys:
        value = values.get(key)
        if value is None:
            continue
        if isinstance(value, (list, tuple)) and key.endswith(("_mm", "rpy_deg")):
            out.append((key, " ".join(f"{float(x):g}" for x in value)))
        elif isinstance(value, (list, tuple)):
            names = joint_names if len(joint_names) == len(value) else \
                [f"joint{i + 1}" for i in range(len(value))]
            out += [(f"{key}.{n}", f"{float(x):g}") for n, x in zip(names, value)]
        else:
            out.append((key, f"{float(value):g}" if isinstance(value, (int, float)) else str(value)))
    return out
