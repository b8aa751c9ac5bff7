"""Reading a run folder: the one loader every part of the report goes through.

A run folder (``seqrun/service/runlog.py``) holds ``report.json`` (summary and per-step results),
``events.jsonl`` (every executor event, one per line) and ``trace.log`` (CAN frames). The
loader tolerates what a killed or older run leaves: a missing or ``running`` report.json,
a torn last line in events.jsonl, events without the per-cycle fields of newer versions.
Nothing here draws or writes; :mod:`seqrun.report.figures` computes, the rest renders.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import ValidationError

from seqrun.arm.description import ArmDescription
from seqrun.errors import UserInputError
from seqrun.arm.tracking import sample_time, velocity_window, windowed_velocity

#: Event types that carry one reading of the whole arm.
SAMPLE_EVENTS = ("setpoint", "measurement")


@dataclass
class Series:
    """Every reading of the arm in time order (samples × joints, degrees, deg/s).

    ``planned`` and ``planned_vel`` are NaN where no plan was streamed (waits, checkpoints);
    ``state`` is the short state byte of each module (-1 where the log has none);
    ``measured_vel`` is the windowed estimate of :mod:`seqrun.arm.tracking`.
    """

    t: np.ndarray
    step: np.ndarray
    streamed: np.ndarray          # True for setpoint samples (a plan was being streamed)
    planned: np.ndarray
    measured: np.ndarray
    planned_vel: np.ndarray
    measured_vel: np.ndarray
    state: np.ndarray
    #: Each joint's own sample time (samples × joints): ``t`` unless the joints of a
    #: reading answered apart (``read_t`` per joint).
    t_joint: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.t)


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
    events: list[dict]
    arm: ArmDescription | None
    steps: list[StepView]
    series: Series
    fault: dict[str, Any] | None       # with "t" when the event log has the fault event
    checkpoints: list[dict]
    trace: dict[str, int] | None       # frames sent / received, when trace.log is there
    run_started: dict[str, Any]
    torn_lines: int = 0                # unreadable lines in events.jsonl (a killed run)
    #: record.json of the run folder (inputs with sha256, git state, zero), when written.
    record: dict[str, Any] = field(default_factory=dict)

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
        return [f"j{i + 1}" for i in range(self.series.measured.shape[1])]

    def of_type(self, *types: str) -> list[dict]:
        return [e for e in self.events if e.get("type") in types]


def load_run(folder: str | Path, *, arm: ArmDescription | None = None) -> RunData:
    """Read a run folder. ``arm`` stands in for the arm description when the event log does
    not carry one (runs of older versions). Raises :class:`UserInputError` (one line) when
    the folder is not a run folder."""
    folder = Path(folder)
    if not folder.is_dir():
        raise UserInputError(f"{folder}: no such run folder")
    events_path = folder / "events.jsonl"
    if not events_path.is_file() and not (folder / "report.json").is_file():
        raise UserInputError(f"{folder}: not a run folder (no events.jsonl, no report.json)")
    # A run refused by validation leaves report.json (and record.json) only.
    events, torn = read_events(events_path) if events_path.is_file() else ([], 0)
    report = _read_json(folder / "report.json")
    trace = _trace_summary(folder / "trace.log")
    data = from_records(report, events, arm=arm, folder=folder, trace=trace, torn_lines=torn)
    data.record = _read_json(folder / "record.json")
    return data


def read_events(path: Path) -> tuple[list[dict], int]:
    """Every parseable line of events.jsonl, and how many were not (a torn last line)."""
    events, torn = [], 0
    with open(path, encoding="utf-8", errors="replace") as f:
        for line in f:
            if not line.strip():
                continue
            try:
                event = json.loads(line)
            except json.JSONDecodeError:
                torn += 1
                continue
            if isinstance(event, dict) and "type" in event:
                events.append(event)
    return events, torn


def _read_json(path: Path) -> dict:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def _trace_summary(path: Path) -> dict[str, int] | None:
    """Frames sent and received (candump lines end in T or R); no full parse."""
    if not path.is_file():
        return None
    sent = received = 0
    with open(path, "rb") as f:
        for line in f:
            end = line.rstrip()[-2:]
            if end == b" T":
                sent += 1
            elif end == b" R":
                received += 1
    return {"sent": sent, "received": received, "bytes": path.stat().st_size}


def from_records(report: dict, events: list[dict], *, arm: ArmDescription | None = None,
                 folder: Path | None = None, trace: dict | None = None,
                 torn_lines: int = 0) -> RunData:
    """RunData from an already-read report and event list."""
    started = next((e for e in events if e.get("type") == "run_started"), {})
    if arm is None and isinstance(started.get("arm"), dict):
        try:
            arm = ArmDescription.model_validate(started["arm"])
        except ValidationError:
            arm = None
    steps = _steps(report, events)
    fault = _fault(report, events)
    checkpoints = report.get("checkpoints")
    if not isinstance(checkpoints, list):
        checkpoints = [dict(step=e.get("step"), **{k: v for k, v in e.items()
                                                   if k not in ("t", "type", "step")})
                       for e in events if e.get("type") == "checkpoint"]
    data = RunData(folder, report, events, arm, steps, _empty_series(arm), fault,
                   checkpoints, trace, started, torn_lines)
    data.series = _series(events, data.velocity_window_s,
                          arm.dof if arm is not None else None)
    return data


def _steps(report: dict, events: list[dict]) -> list[StepView]:
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
    for e in events:
        kind, number = e.get("type"), e.get("step")
        if number is None:
            continue
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
    return [views[n] for n in sorted(views)]


def _fault(report: dict, events: list[dict]) -> dict | None:
    fault = report.get("fault")
    event = next((e for e in reversed(events) if e.get("type") == "fault"), None)
    if fault is None and event is None:
        return None
    merged = dict(event or {})
    merged.pop("type", None)
    merged.update(fault or {})
    if event is not None:
        merged["t"] = event["t"]
    return merged


def _empty_series(arm: ArmDescription | None) -> Series:
    n = arm.dof if arm is not None else 0
    empty = np.zeros((0, n))
    return Series(np.zeros(0), np.zeros(0, int), np.zeros(0, bool), empty, empty, empty,
                  empty, np.zeros((0, n), int))


def _series(events: list[dict], window_s: float, dof: int | None) -> Series:
    if dof is None:
        dof = next((len(_joints(e)) for e in events
                    if e.get("type") in SAMPLE_EVENTS and _joints(e)), 0)
    # A reading without a full set of joints (another version, a hand-edited log) is left
    # out rather than failing the whole report.
    samples = [e for e in events if e.get("type") in SAMPLE_EVENTS
               and isinstance(e.get("t"), (int, float)) and len(_joints(e)) == dof
               and (e["type"] != "setpoint" or len(e.get("planned_deg") or ()) == dof)]
    n = len(samples)
    t = np.empty(n)
    step = np.zeros(n, int)
    streamed = np.zeros(n, bool)
    planned = np.full((n, dof), np.nan)
    measured = np.full((n, dof), np.nan)
    planned_vel = np.full((n, dof), np.nan)
    state = np.full((n, dof), -1, int)
    t_joint = np.empty((n, dof))
    for i, e in enumerate(samples):
        # a reading's time is when the joints answered (read_t: one, or one per joint),
        # where the log has it
        read_t = e.get("read_t")
        if isinstance(read_t, list) and len(read_t) == dof:
            t[i] = sample_time(read_t)
            t_joint[i] = read_t
        else:
            t[i] = read_t if isinstance(read_t, (int, float)) else e["t"]
            t_joint[i] = t[i]
        step[i] = e.get("step") or 0
        measured[i] = _joints(e)
        if e["type"] == "setpoint":
            streamed[i] = True
            planned[i] = e["planned_deg"]
            if len(e.get("planned_vel_deg_s") or ()) == dof:
                planned_vel[i] = e["planned_vel_deg_s"]
        if len(e.get("state") or ()) == dof:
            state[i] = e["state"]
    order = np.argsort(t, kind="stable")
    t, step, streamed, t_joint = t[order], step[order], streamed[order], t_joint[order]
    planned, measured, planned_vel, state = (planned[order], measured[order],
                                             planned_vel[order], state[order])
    measured_vel = (windowed_velocity(t, measured, window_s, t_joint) if n
                    else measured.copy())
    return Series(t, step, streamed, planned, measured, planned_vel, measured_vel, state,
                  t_joint)


def _joints(event: dict) -> list:
    """The measured joints of a reading (``measured_deg`` of a cycle, ``joints_deg`` of a
    monitoring reading)."""
    value = event.get("measured_deg", event.get("joints_deg"))
    return value if isinstance(value, list) else []
