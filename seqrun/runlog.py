"""The run folder: everything a run leaves behind, written as the run goes.

``runs/<time>-<name>/``
  trace.log     every CAN frame sent and received, candump format (``can.LogReader`` reads it)
  events.jsonl  one executor event per line
  report.json   status, exit code, timing, per-step results, fault; rewritten after each
                step so that a killed run still leaves a readable report ("running")
  junit.xml     one test case per step and one per checkpoint, measured values as
                properties, for CI dashboards
  report.html   drawn after the run from the files above (seqrun/report/)

Every file is flushed as it is written: a run killed with SIGKILL leaves a readable log.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
from pathlib import Path
from typing import Any
from xml.sax.saxutils import escape, quoteattr

import can

from seqrun.executor import RunResult, StepResult


def default_run_dir(sequence_name: str, root: Path = Path("runs")) -> Path:
    stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    safe = "".join(c if c.isalnum() or c in "-_" else "-" for c in sequence_name)[:60]
    return root / f"{stamp}-{safe}"


def _now_iso() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="milliseconds")


def _atomic_write(path: Path, text: str) -> None:
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


class RunLog:
    """Event listener and frame listener writing one run folder."""

    def __init__(self, folder: Path, meta: dict[str, Any]) -> None:
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.meta = dict(meta)
        self.started_iso = _now_iso()
        self._events = open(self.folder / "events.jsonl", "w", encoding="utf-8")
        self._trace = can.Logger(str(self.folder / "trace.log"))
        self._closed = False
        self._steps: dict[int, dict] = {}
        self._joint_names: list[str] = []
        self._write_report({"status": "running", "exit_code": None})

    # Listeners -------------------------------------------------------------------
    def on_event(self, event: dict) -> None:
        if self._closed:
            return
        self._events.write(json.dumps(event, separators=(",", ":")) + "\n")
        self._events.flush()
        if event["type"] == "run_started":   # names for the per-joint JUnit properties
            self._joint_names = [j.get("name", "") for j in
                                 (event.get("arm") or {}).get("joints", [])]
        if event["type"] == "step_finished":
            self._steps[event.get("step", 0)] = event
            self._write_report({"status": "running", "exit_code": None})

    def on_frame(self, msg: can.Message) -> None:
        if self._closed:
            return
        self._trace.on_message_received(msg)
        self._trace.file.flush()

    # Final report -----------------------------------------------------------------
    def finish(self, result: RunResult) -> dict:
        report = {
            "status": result.status,
            "exit_code": result.exit_code,
            "message": result.message,
            "duration_s": round(result.duration_s, 4),
            "planned_duration_s": round(result.planned_duration_s, 4),
            "fault": result.fault,
            "latched_at_start": result.latched_at_start,
            "steps": [s.as_dict() for s in result.steps],
            "checkpoints": [_checkpoint(s) for s in result.steps if s.kind == "checkpoint"
                            and s.status != "skipped"],
            "not_verified": result.not_verified,
            "min_heights_mm": result.min_heights_mm,
        }
        full = self._write_report(report, ended=True)
        _atomic_write(self.folder / "junit.xml", junit_xml(self.meta.get("sequence", "sequence"),
                                                          result, self._joint_names))
        return full

    def _write_report(self, body: dict, ended: bool = False) -> dict:
        report = {"sequence": self.meta.get("sequence"), "file": self.meta.get("file"),
                  "start": self.started_iso, "end": _now_iso() if ended else None,
                  **{k: v for k, v in self.meta.items() if k not in ("sequence", "file")},
                  **body}
        if not ended and self._steps:
            report["steps_finished"] = sorted(self._steps)
        _atomic_write(self.folder / "report.json", json.dumps(report, indent=2, default=str))
        return report

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._events.close()
        self._trace.stop()


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


def _junit_suite(name: str, classname: str, result: RunResult, steps: list[StepResult],
                 keys: tuple[str, ...], joint_names: list[str], *,
                 checkpoint: bool = False) -> list[str]:
    failures = sum(1 for s in steps if s.status in ("failed", "aborted"))
    skipped = sum(1 for s in steps if s.status in ("skipped", "pending"))
    time = sum(s.duration_s or 0.0 for s in steps) if checkpoint else result.duration_s
    lines = [f'<testsuite name={quoteattr(name)} tests="{len(steps)}" '
             f'failures="{failures}" skipped="{skipped}" time="{time:.3f}">']
    for s in steps:
        # A step without a label is described starting with its kind ("confirm: …",
        # "move to pose …"): no second kind in front of it.
        kind = "" if s.label.split(":")[0].split(" ")[0] == s.kind else f"{s.kind}: "
        title = f"{s.number:02d} {s.label}" if checkpoint else f"{s.number:02d} {kind}{s.label}"
        duration = f"{s.duration_s:.3f}" if s.duration_s is not None else "0"
        lines.append(f'  <testcase classname={quoteattr(classname)} name={quoteattr(title)} '
                     f'file={quoteattr(s.location)} time="{duration}">')
        properties = _junit_properties(s, keys, joint_names)
        if properties:
            lines.append("    <properties>")
            lines += [f"      <property name={quoteattr(k)} value={quoteattr(v)}/>"
                      for k, v in properties]
            lines.append("    </properties>")
        if s.status in ("failed", "aborted"):
            msg = s.detail.get("error") or result.message
            lines.append(f'    <failure message={quoteattr(str(msg))}>{escape(str(msg))}</failure>')
        elif s.status in ("skipped", "pending"):
            lines.append('    <skipped message="not run"/>')
        lines.append("  </testcase>")
    lines.append("</testsuite>")
    return lines


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
