"""Reading a run folder: the one loader every part of the report goes through.

A run folder (``seqrun/service/runlog.py``) holds ``report.json`` (summary and per-step results),
``events.jsonl`` (every executor event, one per line) and the CAN trace (``trace.log.gz``,
or ``trace.log`` of older runs). The loader tolerates what a killed or older run leaves: a
missing or ``running`` report.json, a torn last line in events.jsonl, events without the
per-cycle fields of newer versions.

events.jsonl is read once, as a stream: the arm's readings (hundreds of thousands an hour)
are folded into per-step summaries and decimated plot lines (:mod:`seqrun.report.summary`)
and never held all at once; of the other events, the steps' are folded into the step views
and only the few the page shows are kept. :meth:`RunData.readings` streams the readings
again at full resolution (the CSV export). Nothing here draws or writes;
:mod:`seqrun.report.figures` computes, the rest renders.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Iterator

from pydantic import ValidationError

from seqrun.arm.description import ArmDescription
from seqrun.errors import UserInputError
from seqrun.arm.tracking import velocity_window
from seqrun.report.readings import SAMPLE_EVENTS, EventLines, Series, split
from seqrun.report.summary import Overview, StepSummary, SummaryBuilder
from seqrun.runfolder.names import events_path

#: Points per plotted line at most (a min/max envelope beyond).
MAX_POINTS = 3000
#: Events the page reads besides the steps' (which are folded into the step views).
KEPT_EVENTS = ("run_started", "preflight", "fault", "operator_abort", "run_finished",
               "checkpoint", "zero_reference")

__all__ = ["MAX_POINTS", "RunData", "SAMPLE_EVENTS", "Series", "StepView", "load_run"]


@dataclass
class StepView:
    """One step as the report shows it: report.json's result merged with its events."""

    number: int
    kind: str
    label: str
    location: str
    status: str
    started_t: float | None = None
    finished_t: float | None = None
    duration_s: float | None = None
    planned_duration_s: float | None = None
    detail: dict[str, Any] = field(default_factory=dict)
    move: dict[str, Any] | None = None     # the last move_planned event of the step


@dataclass
class RunData:
    folder: Path | None
    report: dict[str, Any]
    #: The events the page reads (:data:`KEPT_EVENTS`), in order; the readings and the
    #: steps' events are folded into ``overview``, ``step_summaries`` and ``steps``.
    events: list[dict]
    arm: ArmDescription | None
    steps: list[StepView]
    overview: Overview
    step_summaries: dict[int, StepSummary]
    fault: dict[str, Any] | None       # with "t" when the event log has the fault event
    checkpoints: list[dict]
    trace: dict[str, Any] | None       # frames sent / received, when the trace is there
    run_started: dict[str, Any]
    torn_lines: int = 0                # unreadable lines in events.jsonl (a killed run)
    #: record.json of the run folder (inputs with sha256, git state, zero), when written.
    record: dict[str, Any] = field(default_factory=dict)
    #: Every event of the log, readings included.
    event_count: int = 0
    #: Joints per reading (the arm's; else the log's).
    dof: int = 0
    #: Where the events come from again (events.jsonl, or the list they were given as).
    source: Iterable[dict] = field(default=(), repr=False)
    #: What of the folder is cut short or lacks its end (seqrun.runfolder.integrity).
    incomplete: list[str] = field(default_factory=list)
    #: inputs/ files that are not as record.json recorded them (changed after the run).
    inputs_changed: list[str] = field(default_factory=list)

    @property
    def virtual_time(self) -> bool:
        started = self.run_started
        if "virtual_time" in started:
            return bool(started["virtual_time"])
        return "virtual time" in str(self.report.get("bus", "")).lower()

    @property
    def dry_run(self) -> bool:
        return bool(self.run_started.get("dry_run"))

    @property
    def cycle_s(self) -> float | None:
        value = self.run_started.get("cycle_s")
        if value is None and self.arm is not None:
            return 1.0 / self.arm.control.cycle_hz
        return value

    @property
    def velocity_window_s(self) -> float:
        value = self.run_started.get("velocity_window_s")
        return float(value) if value else velocity_window(self.cycle_s or 0.01)

    @property
    def joint_names(self) -> list[str]:
        if self.arm is not None:
            return self.arm.joint_names
        return [f"j{i + 1}" for i in range(self.dof)]

    @property
    def reading_count(self) -> int:
        return self.overview.readings

    def of_type(self, *types: str) -> list[dict]:
        return [e for e in self.events if e.get("type") in types]

    def readings(self) -> Iterator[Series]:
        """The arm's readings at full resolution, a chunk at a time (read anew)."""
        for item in split(self.source, dof=lambda: self.dof or None,
                          window_s=lambda: self.velocity_window_s):
            if isinstance(item, Series):
                yield item


def load_run(folder: str | Path, *, arm: ArmDescription | None = None) -> RunData:
    """Read a run folder. ``arm`` stands in for the arm description when the event log does
    not carry one (runs of older versions). Raises :class:`UserInputError` (one line) when
    the folder is not a run folder."""
    folder = Path(folder)
    if not folder.is_dir():
        raise UserInputError(f"{folder}: no such run folder")
    log = events_path(folder)   # events.jsonl.gz, or an older run's events.jsonl
    if log is None and not (folder / "report.json").is_file():
        raise UserInputError(f"{folder}: not a run folder (no events.jsonl, no report.json)")
    # A run refused by validation leaves report.json (and record.json) only.
    lines: Iterable[dict] = EventLines(log) if log is not None else []
    report = _read_json(folder / "report.json")
    data = from_records(report, lines, arm=arm, folder=folder, trace=_trace_summary(folder))
    data.torn_lines = lines.torn if isinstance(lines, EventLines) else 0
    data.record = _read_json(folder / "record.json")
    from seqrun.runfolder.integrity import changed_inputs, incomplete

    data.incomplete = incomplete(folder, thorough=True)
    data.inputs_changed = changed_inputs(folder)
    return data


def _read_json(path: Path) -> dict:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def _trace_summary(folder: Path) -> dict[str, Any] | None:
    """Frames sent and received (candump lines end in T or R); no full parse. A trace
    cut short (a killed run) counts what it holds."""
    from seqrun.runfolder.logfile import read_lines
    from seqrun.runfolder.names import trace_path

    path = trace_path(folder)
    if path is None:
        return None
    sent = received = 0
    for line in read_lines(path):
        end = line.rstrip()[-2:]
        if end == b" T":
            sent += 1
        elif end == b" R":
            received += 1
    return {"sent": sent, "received": received, "bytes": path.stat().st_size,
            "file": path.name}


def from_records(report: dict, events: Iterable[dict], *, arm: ArmDescription | None = None,
                 folder: Path | None = None, trace: dict | None = None,
                 torn_lines: int = 0) -> RunData:
    """RunData from an already-read report and the events (an iterable read once now, and
    again by :meth:`RunData.readings`)."""
    views = _report_steps(report)
    data = RunData(folder, report, [], arm, [], Overview(), {}, None, [], trace, {},
                   torn_lines, source=events)
    builder: SummaryBuilder | None = None
    fault_event = None
    checkpoint_events = []
    others = 0
    for item in split(events, dof=lambda: data.arm.dof if data.arm is not None else None,
                      window_s=lambda: data.velocity_window_s):
        if isinstance(item, Series):
            if builder is None:
                data.dof = item.measured.shape[1]
                builder = SummaryBuilder(data.arm, data.dof, data.velocity_window_s,
                                         MAX_POINTS)
            builder.add(item)
            continue
        others += 1
        kind = item.get("type")
        if kind == "run_started" and not data.run_started:
            data.run_started = item
            if arm is None and isinstance(item.get("arm"), dict):
                try:
                    data.arm = ArmDescription.model_validate(item["arm"])
                except ValidationError:
                    data.arm = None
        elif kind == "fault":
            fault_event = item
        elif kind == "checkpoint":
            checkpoint_events.append(item)
        _fold_step_event(views, item)
        if kind in KEPT_EVENTS:
            data.events.append(item)
    if builder is not None:
        data.overview, data.step_summaries = builder.finish()
    elif data.arm is not None:
        data.dof = data.arm.dof
    data.event_count = others + data.overview.readings
    data.steps = [views[n] for n in sorted(views)]
    data.fault = _fault(report, fault_event)
    checkpoints = report.get("checkpoints")
    if not isinstance(checkpoints, list):
        checkpoints = [dict(step=e.get("step"), **{k: v for k, v in e.items()
                                                   if k not in ("t", "type", "step")})
                       for e in checkpoint_events]
    data.checkpoints = checkpoints
    return data


def _report_steps(report: dict) -> dict[int, StepView]:
    views: dict[int, StepView] = {}
    for s in report.get("steps") or []:
        if not isinstance(s, dict) or "number" not in s:
            continue
        known = ("number", "kind", "label", "location", "status", "duration_s",
                 "planned_duration_s")
        views[s["number"]] = StepView(
            s["number"], s.get("kind", "?"), s.get("label", ""), s.get("location", ""),
            s.get("status", "?"), duration_s=s.get("duration_s"),
            planned_duration_s=s.get("planned_duration_s"),
            detail={k: v for k, v in s.items() if k not in known})
    return views


def _fold_step_event(views: dict[int, StepView], e: dict) -> None:
    """What a step's event adds to its view (report.json's result comes first)."""
    kind, number = e.get("type"), e.get("step")
    if number is None:
        return
    if kind == "step_started":
        view = views.setdefault(number, StepView(number, e.get("kind", "?"),
                                                 e.get("label", ""),
                                                 e.get("location", ""), "running"))
        view.started_t = e["t"]
    elif kind == "move_planned" and number in views:
        views[number].move = e
    elif kind == "step_finished" and number in views:
        view = views[number]
        view.finished_t = e["t"]
        if view.status in ("running", "pending", "?"):
            view.status = e.get("status", "passed")
            view.duration_s = e.get("duration_s")
            view.planned_duration_s = e.get("planned_duration_s")
        skip = ("t", "type", "step", "status", "duration_s", "planned_duration_s")
        for k, v in e.items():
            if k not in skip:
                view.detail.setdefault(k, v)
    elif kind in ("fault", "operator_abort") and number in views:
        views[number].finished_t = views[number].finished_t or e["t"]


def _fault(report: dict, event: dict | None) -> dict | None:
    fault = report.get("fault")
    if fault is None and event is None:
        return None
    merged = dict(event or {})
    merged.pop("type", None)
    merged.update(fault or {})
    if event is not None:
        merged["t"] = event["t"]
    return merged
