"""Trends over a campaign's runs: one value per run, in the order the runs started.

``seqrun trend`` reads only run folders: each one's report.json (its steps' figures,
checkpoints, lowest heights) and record.json (the sha256 of every input), and, for the
limits a run was held to, the arm file the run copied into its inputs/. A series is one
value of one step of one sequence (``(sequence, step, metric, item)``) across the runs:

- ``duration_s``: each step's duration (and the whole run's, step ``run``);
- ``checkpoint_error_mm``: a checkpoint's position error, against its tolerance;
- ``following_error_deg``: a move's largest following error over its joints, against the
  arm's bound (``control.max_following_error_deg``);
- ``peak_current_a``: a step's peak motor current, when the run recorded one;
- ``clearance_mm``: the lowest height of each guarded point over the run, against its
  guard's line (``min_z_mm``).

A run that has the step but not the figure (an older version, currents not read) gives
"not recorded"; a run that never reached the step "not run": neither is ever filled in.
Runs with the same inputs (the same set of sha256) but different verdicts are "flaky".
Nothing here draws; :mod:`seqrun.report.trend_page` renders.
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from seqrun.errors import UserInputError

METRICS = ("clearance_mm", "duration_s", "checkpoint_error_mm", "peak_current_a",
           "following_error_deg")
#: Metrics whose limit is a minimum (the value must stay above it); the others' a maximum.
LOWER_LIMITS = ("clearance_mm",)
NOT_RECORDED = "not recorded"
NOT_RUN = "not run"
#: A step's status in report.json when the run never got to it (a fault before, a run
#: started at a later step).
STEPS_NOT_RUN = ("pending", "skipped")
#: The step name of the figures of a whole run (its duration, its lowest heights).
RUN_STEP = "run"


@dataclass
class TrendRun:
    """One run folder as the trend reads it."""

    folder: Path
    name: str
    sequence: str
    start: str | None
    status: str
    report: dict[str, Any]
    #: A digest of the sorted sha256 of the run's inputs (None: the run recorded none).
    inputs: str | None
    #: ``--sim-fault`` specs the run was given (an injected fault explains a verdict).
    faults: list[str] = field(default_factory=list)
    #: The guards' lines (mm) and the following-error bound (deg) of the run's own arm
    #: file (its inputs/ copy), where it can be read.
    guard_min_mm: dict[str, float] = field(default_factory=dict)
    following_bound_deg: float | None = None


@dataclass
class Point:
    run: TrendRun
    #: The figure, or :data:`NOT_RECORDED` / :data:`NOT_RUN`.
    value: float | str
    limit: float | None = None
    limit_source: str = ""
    #: The step's own verdict in this run (the run's for step ``run``).
    status: str = ""

    @property
    def number(self) -> float | None:
        return self.value if isinstance(self.value, float) else None


@dataclass
class Series:
    sequence: str
    step: str          # the step number, or "run"
    label: str
    metric: str
    item: str          # a guard point ("desk:wrist"), a joint ("j4"), or ""
    points: list[Point] = field(default_factory=list)

    @property
    def title(self) -> str:
        step = "whole run" if self.step == RUN_STEP else f"step {self.step}"
        label = f" {self.label}" if self.label else ""
        item = f" [{self.item}]" if self.item else ""
        return f"{self.sequence} · {step}{label} · {self.metric}{item}"

    @property
    def recorded(self) -> list[Point]:
        return [p for p in self.points if p.number is not None]

    @property
    def first(self) -> float | None:
        recorded = self.recorded
        return recorded[0].number if recorded else None

    @property
    def last(self) -> float | None:
        recorded = self.recorded
        return recorded[-1].number if recorded else None

    @property
    def drift(self) -> float | None:
        """Last recorded value minus the first."""
        if self.first is None or self.last is None:
            return None
        return _round(self.last - self.first)

    def drift_of(self, point: Point) -> float | None:
        if point.number is None or self.first is None:
            return None
        return _round(point.number - self.first)

    @property
    def worst(self) -> Point | None:
        """The recorded point nearest its limit side: the lowest clearance, the highest of
        the others."""
        recorded = self.recorded
        if not recorded:
            return None
        pick = min if self.metric in LOWER_LIMITS else max
        return pick(recorded, key=lambda p: p.number or 0.0)

    def margin_of(self, point: Point) -> float | None:
        """How far the point is inside its limit (negative: beyond it)."""
        if point.number is None or point.limit is None:
            return None
        if self.metric in LOWER_LIMITS:
            return _round(point.number - point.limit)
        return _round(point.limit - point.number)

    @property
    def limit(self) -> Point | None:
        """The last point that knows its limit."""
        return next((p for p in reversed(self.points) if p.limit is not None), None)


@dataclass
class FlakyGroup:
    """Runs of one sequence with the same inputs and different verdicts."""

    sequence: str
    inputs: str
    runs: list[TrendRun]

    @property
    def verdicts(self) -> dict[str, int]:
        counts: dict[str, int] = {}
        for run in self.runs:
            counts[run.status] = counts.get(run.status, 0) + 1
        return counts


@dataclass
class Trend:
    runs: list[TrendRun]
    series: list[Series]
    flaky: list[FlakyGroup]
    #: Folders that could not be read, as one line each.
    skipped: list[str] = field(default_factory=list)


def _round(x: float) -> float:
    return round(x, 6) + 0.0   # (+ 0.0: no "-0.0")


def _read_json(path: Path) -> Any:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError):
        return None


def _number(value: Any) -> float | None:
    """A recorded figure: a number (the largest of a per-joint list), None if absent."""
    if isinstance(value, bool):
        return None
    if isinstance(value, (int, float)):
        return float(value)
    if isinstance(value, list):
        numbers = [float(v) for v in value
                   if isinstance(v, (int, float)) and not isinstance(v, bool)]
        return max(numbers, key=abs) if numbers else None
    return None


# --------------------------------------------------------------------------- reading
def run_folders(paths: list[Path]) -> list[Path]:
    """The run folders among ``paths``: each is a run folder itself (report.json, or the
    parts of a run of several arms), or a folder of runs (which may hold none yet)."""
    folders: list[Path] = []
    for path in paths:
        path = Path(path)
        if not path.is_dir():
            raise UserInputError(f"{path}: no such folder")
        if _is_run(path):
            folders.append(path)
            continue
        folders += sorted(p for p in _with_suites(path) if _is_run(p))
    return folders


def _with_suites(path: Path) -> list[Path]:
    """The folders in ``path``, a suite's folder replaced by its runs (docs/suites.md)."""
    from seqrun.runfolder.names import is_suite_folder, runs_of_suite

    found: list[Path] = []
    for p in sorted(path.iterdir()):
        if p.is_dir():
            found += runs_of_suite(p) if is_suite_folder(p) else [p]
    return found


def _is_run(folder: Path) -> bool:
    """A run of one arm (report.json), or of several (arms.json beside a part per arm)."""
    return (folder / "report.json").is_file() or (folder / "arms.json").is_file()


def read_runs(folders: list[Path]) -> tuple[list[TrendRun], list[str]]:
    """Every run of ``folders`` (a run of several arms: one per arm), oldest first; and a
    line for each folder whose report.json cannot be read."""
    runs: list[TrendRun] = []
    skipped: list[str] = []
    arms: dict[str, tuple[dict[str, float], float | None]] = {}
    for folder in folders:
        parts = [(folder, "")] if (folder / "report.json").is_file() else [
            (p, p.name) for p in sorted(folder.iterdir()) if (p / "report.json").is_file()]
        for part, arm_id in parts:
            report = _read_json(part / "report.json")
            if not isinstance(report, dict):
                skipped.append(f"{part}: report.json unreadable")
                continue
            runs.append(_trend_run(part, report, arm_id, arms))
    runs.sort(key=lambda r: (r.start or "", str(r.folder)))
    return runs, skipped


def _trend_run(folder: Path, report: dict, arm_id: str,
               arms: dict[str, tuple[dict[str, float], float | None]]) -> TrendRun:
    record = _read_json(folder / "record.json")
    record = record if isinstance(record, dict) else {}
    sequence = report.get("sequence") or record.get("sequence")
    sequence = str(sequence) if isinstance(sequence, str) and sequence else NOT_RECORDED
    if arm_id:
        sequence += f" (arm {arm_id})"
    start = report.get("start")
    status = report.get("status")
    faults = report.get("faults")
    run = TrendRun(folder, folder.name if not arm_id else f"{folder.parent.name}/{arm_id}",
                   sequence, start if isinstance(start, str) else None,
                   status if isinstance(status, str) else NOT_RECORDED, report,
                   _inputs_digest(record, report),
                   [str(f) for f in faults] if isinstance(faults, list) else [])
    run.guard_min_mm, run.following_bound_deg = _arm_limits(folder, report, arms)
    return run


def _inputs_digest(record: dict, report: dict) -> str | None:
    """One name for the run's inputs: the sha256 of their sorted sha256 (record.json's,
    else report.json's list)."""
    for source in (record.get("inputs"), report.get("inputs")):
        if isinstance(source, list):
            hashes = sorted(str(i["sha256"]) for i in source
                            if isinstance(i, dict) and isinstance(i.get("sha256"), str))
            if hashes:
                return hashlib.sha256("\n".join(hashes).encode()).hexdigest()
    return None


def _arm_limits(folder: Path, report: dict,
                cache: dict[str, tuple[dict[str, float], float | None]]
                ) -> tuple[dict[str, float], float | None]:
    """The guards' lines and the following-error bound of the arm file the run copied
    into inputs/ (``({}, None)`` when it has none or it does not load)."""
    files = [str(i["file"]) for i in _list(report.get("inputs"))
             if isinstance(i, dict) and i.get("kind") == "arm" and isinstance(i.get("file"),
                                                                              str)]
    path = folder / "inputs" / files[0] if files else None
    if path is None or not path.is_file():
        return {}, None
    try:
        key = hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError:
        return {}, None
    if key not in cache:
        from seqrun.arm.description import load_arm

        try:
            arm = load_arm(path)
        except Exception:  # noqa: BLE001 - an arm file this version cannot read: no limits
            cache[key] = ({}, None)
        else:
            cache[key] = ({g.name: float(g.min_z_mm) for g in arm.workspace.guards},
                          float(arm.control.max_following_error_deg))
    return cache[key]


# --------------------------------------------------------------------------- series
def _list(value: Any) -> list:
    """A field that should be a list (anything else, as an odd older file has it: none)."""
    return value if isinstance(value, list) else []


def _steps(report: dict) -> list[dict]:
    return [s for s in _list(report.get("steps")) if isinstance(s, dict)
            and isinstance(s.get("number"), int) and not isinstance(s.get("number"), bool)]


def _step_metrics(step: dict) -> list[str]:
    """The metrics a step has a series for (whether or not this run recorded them)."""
    kind = step.get("kind")
    metrics = ["duration_s"]
    if kind == "checkpoint" or "position_error_mm" in step:
        metrics.append("checkpoint_error_mm")
    if kind == "move" or "max_following_error_deg" in step:
        metrics.append("following_error_deg")
    if kind == "move" or "peak_current_a" in step:
        metrics.append("peak_current_a")
    return metrics


def _step_point(run: TrendRun, step: dict | None, metric: str) -> Point:
    status = str(step.get("status") or NOT_RECORDED) if step is not None else NOT_RUN
    if step is None or status in STEPS_NOT_RUN:
        return Point(run, NOT_RUN, status=status)
    if metric == "duration_s":
        return Point(run, _or_not_recorded(_number(step.get("duration_s"))), status=status)
    if metric == "checkpoint_error_mm":
        limit = _number(step.get("position_tolerance_mm"))
        return Point(run, _or_not_recorded(_number(step.get("position_error_mm"))), limit,
                     "the checkpoint's position_tolerance_mm" if limit is not None else "",
                     status)
    if metric == "following_error_deg":
        bound = run.following_bound_deg
        return Point(run, _or_not_recorded(_number(step.get("max_following_error_deg"))),
                     bound, "the arm file's control.max_following_error_deg"
                     if bound is not None else "", status)
    return Point(run, _or_not_recorded(_number(step.get("peak_current_a"))), status=status)


def _or_not_recorded(value: float | None) -> float | str:
    return NOT_RECORDED if value is None else value


def build_series(runs: list[TrendRun], metrics: tuple[str, ...] = METRICS,
                 step_filter: str | None = None) -> list[Series]:
    """The series of ``runs`` (each run a point of every series of its sequence)."""
    series: dict[tuple[str, str, str, str, str], Series] = {}
    by_sequence: dict[str, list[TrendRun]] = {}
    for run in runs:
        by_sequence.setdefault(run.sequence, []).append(run)
    for sequence, seq_runs in by_sequence.items():
        keys: list[tuple[str, str, str, str, str]] = []

        def add(key: tuple[str, str, str, str, str]) -> None:
            if key not in series:
                series[key] = Series(sequence, key[1], key[2], key[3], key[4])
                keys.append(key)

        # The steps of every run, by number and label (a sequence edited between runs: a
        # step whose label changed is another series).
        for run in seq_runs:
            for step in _steps(run.report):
                for metric in _step_metrics(step):
                    if metric in metrics and _step_matches(step, step_filter):
                        add((sequence, str(step["number"]), str(step.get("label") or ""),
                             metric, ""))
            if step_filter in (None, RUN_STEP):
                if "duration_s" in metrics:
                    add((sequence, RUN_STEP, "", "duration_s", ""))
                if "clearance_mm" in metrics:
                    heights = run.report.get("min_heights_mm")
                    for point in heights if isinstance(heights, dict) else ():
                        add((sequence, RUN_STEP, "", "clearance_mm", str(point)))
        for key in keys:
            s = series[key]
            for run in seq_runs:
                s.points.append(_point(run, s))
    return sorted(series.values(), key=_series_order)


def _series_order(s: Series) -> tuple:
    step = (1, 0) if s.step == RUN_STEP else (0, int(s.step))
    return (s.sequence, METRICS.index(s.metric), step, s.label, s.item)


def _step_matches(step: dict, wanted: str | None) -> bool:
    return wanted is None or wanted in (str(step["number"]), step.get("label"), step.get("id"))


def _point(run: TrendRun, s: Series) -> Point:
    if s.step == RUN_STEP:
        status = run.status
        if s.metric == "duration_s":
            return Point(run, _or_not_recorded(_number(run.report.get("duration_s"))),
                         status=status)
        heights = run.report.get("min_heights_mm")
        value = _number(heights.get(s.item)) if isinstance(heights, dict) else None
        guard = s.item.split(":", 1)[0]
        limit = run.guard_min_mm.get(guard)
        return Point(run, _or_not_recorded(value), limit,
                     f"guard '{guard}' min_z_mm of the arm file" if limit is not None else "",
                     status)
    step = next((st for st in _steps(run.report) if str(st["number"]) == s.step
                 and str(st.get("label") or "") == s.label), None)
    return _step_point(run, step, s.metric)


def flaky_groups(runs: list[TrendRun]) -> list[FlakyGroup]:
    """Runs of a sequence with the same inputs and more than one verdict (a run still
    running, or killed while it ran, has none yet)."""
    groups: dict[tuple[str, str], list[TrendRun]] = {}
    for run in runs:
        if run.inputs is not None and run.status not in (NOT_RECORDED, "running"):
            groups.setdefault((run.sequence, run.inputs), []).append(run)
    return [FlakyGroup(sequence, inputs, members)
            for (sequence, inputs), members in groups.items()
            if len({r.status for r in members}) > 1]


def trend(paths: list[Path], *, sequence: str | None = None, step: str | None = None,
          metric: str | None = None, limit: float | None = None) -> Trend:
    """The trend of the runs under ``paths`` (raises UserInputError with one line for a
    path that holds no runs, an unknown metric, or a sequence or step no run has)."""
    if metric is not None and metric not in METRICS:
        raise UserInputError(f"--metric {metric}: not a metric (one of {', '.join(METRICS)})")
    if limit is not None and metric is None:
        raise UserInputError("--limit: name the --metric it is a limit of")
    runs, skipped = read_runs(run_folders(paths))
    if sequence is not None:
        names = sorted({r.sequence for r in runs})
        runs = [r for r in runs if r.sequence == sequence
                or Path(str(r.report.get("file") or "")).stem == sequence]
        if not runs:
            raise UserInputError(f"--sequence {sequence}: no run of it (the runs are of "
                                 f"{', '.join(names) or 'nothing'})")
    series = build_series(runs, (metric,) if metric else METRICS, step)
    if step is not None and not series and runs:
        raise UserInputError(f"--step {step}: no step of that number or label in the runs"
                             + (f" with --metric {metric}" if metric else ""))
    if limit is not None:
        for s in series:
            for p in s.points:
                p.limit, p.limit_source = limit, "--limit"
    return Trend(runs, series, flaky_groups(runs), skipped)


# --------------------------------------------------------------------------- outputs
def short(digest: str | None) -> str:
    return digest[:12] if digest else NOT_RECORDED


def _fmt(value: float | None) -> str:
    return "-" if value is None else f"{value:g}"


def summary_lines(t: Trend) -> list[str]:
    """The terminal summary: a line per series, then the flaky groups."""
    lines = []
    for s in t.series:
        worst = s.worst
        recorded = len(s.recorded)
        if worst is None:
            lines.append(f"{s.title}: {NOT_RECORDED} in {len(s.points)} run(s)")
            continue
        limit = s.limit
        against = ""
        if limit is not None and limit.limit is not None:
            margin = s.margin_of(worst)
            against = f", limit {limit.limit:g} (margin {_fmt(margin)})"
        missing = len(s.points) - recorded
        lines.append(f"{s.title}: first {s.first:g}, last {s.last:g}, "
                     f"drift {s.drift:+g}, worst {worst.number:g} ({worst.run.name})"
                     f"{against}; {recorded} run(s)"
                     + (f", {missing} not recorded / not run" if missing else ""))
    for g in t.flaky:
        verdicts = ", ".join(f"{n} {v}" for v, n in g.verdicts.items())
        lines.append(f"FLAKY {g.sequence}: inputs {short(g.inputs)}: {verdicts}: "
                     + ", ".join(f"{r.name} {r.status}"
                                 + (f" (--sim-fault {' '.join(r.faults)})" if r.faults else "")
                                 for r in g.runs))
    lines.append(f"{len(t.series)} series over {len(t.runs)} run(s); "
                 f"{len(t.flaky)} flaky group(s)")
    return lines


CSV_COLUMNS = ("sequence", "step", "label", "metric", "item", "run", "start", "run_status",
               "step_status", "inputs_sha256", "value", "drift_from_first", "limit",
               "limit_source", "margin_to_limit")


def trend_csv(t: Trend) -> str:
    """One row per series and run, in the runs' order."""
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    for s in t.series:
        for p in s.points:
            writer.writerow([s.sequence, s.step, s.label, s.metric, s.item, p.run.name,
                             p.run.start or NOT_RECORDED, p.run.status, p.status,
                             p.run.inputs or NOT_RECORDED,
                             p.value if isinstance(p.value, str) else repr(p.value),
                             _blank(s.drift_of(p)), _blank(p.limit), p.limit_source,
                             _blank(s.margin_of(p))])
    return out.getvalue()


def _blank(value: float | None) -> str:
    return "" if value is None else repr(value)
