"""The requirement matrix: requirement × run -> passed / failed / not run.

``seqrun report --requirements RUN_DIR…`` reads each run folder's report.json (the
``requirements`` summary, else its steps' ``verifies``; a run of several arms: its arms'
parts together) and the campaign's requirements.csv, and writes one self-contained HTML
page (inline CSS, no script, as report.html) and a CSV. Every requirement of the CSV is a
row even when no run verifies it; an id a run verified that the CSV lacks is a row too,
marked so. A run folder of an older version (no ``verifies``) says "not run" throughout.
"""

from __future__ import annotations

import csv
import datetime as _dt
import io
import json
from dataclasses import dataclass, field
from html import escape
from pathlib import Path
from typing import Any

from seqrun.errors import UserInputError
from seqrun.runfolder.requirements import (FAILED, NOT_RUN, PASSED, REQUIREMENTS_NAME,
                                           Requirement, read_requirements, row_error_line,
                                           run_requirements)


@dataclass
class MatrixRun:
    folder: Path
    sequence: str
    start: str
    status: str
    #: What the run says of each requirement it verified (the others: not run).
    results: dict[str, str]


@dataclass
class Matrix:
    requirements: list[Requirement]
    runs: list[MatrixRun]
    #: Where the requirements were read (None: no requirements.csv found).
    source: Path | None = None
    #: Ids runs verified that the requirements.csv does not list.
    unlisted: list[str] = field(default_factory=list)
    #: Malformed rows of the requirements.csv, ``requirements.csv:LINE: message``.
    problems: list[str] = field(default_factory=list)

    def ids(self) -> list[str]:
        return [r.id for r in self.requirements] + self.unlisted

    def cell(self, run: MatrixRun, rid: str) -> str:
        return run.results.get(rid, NOT_RUN)


def _read_json(path: Path) -> Any:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError):
        return None


def _combine(parts: list[dict[str, str]]) -> dict[str, str]:
    """The requirements of a run of several arms: failed when an arm's failed it, passed
    when every arm that verified it passed it, else not run."""
    seen: dict[str, list[str]] = {}
    for part in parts:
        for rid, status in part.items():
            seen.setdefault(rid, []).append(status)
    return {rid: FAILED if FAILED in s else PASSED if all(x == PASSED for x in s) else NOT_RUN
            for rid, s in seen.items()}


def read_run(folder: Path) -> MatrixRun:
    """One run folder as the matrix reads it (UserInputError: not a run folder)."""
    folder = Path(folder)
    report = _read_json(folder / "report.json")
    if isinstance(report, dict):
        return MatrixRun(folder, str(report.get("sequence") or "?"),
                         str(report.get("start") or ""), str(report.get("status") or "?"),
                         run_requirements(report))
    parts = sorted(p for p in folder.iterdir() if (p / "report.json").is_file()) \
        if folder.is_dir() else []
    reports = [r for r in (_read_json(p / "report.json") for p in parts) if isinstance(r, dict)]
    if not reports:
        raise UserInputError(f"{folder}: not a run folder (no readable report.json)")
    summary = _read_json(folder / "arms.json")
    summary = summary if isinstance(summary, dict) else {}
    statuses = [str(r.get("status")) for r in reports]
    return MatrixRun(folder, str(summary.get("sequence") or reports[0].get("sequence") or "?"),
                     min(str(r.get("start") or "") for r in reports),
                     next((s for s in statuses if s != PASSED), PASSED),
                     _combine([run_requirements(r) for r in reports]))


def _requirements_file(runs: list[MatrixRun], project: Path | None) -> Path | None:
    """The campaign's requirements.csv: ``--project``'s, else that of the campaign a run
    recorded (record.json), else the copy in the newest run's inputs/."""
    if project is not None:
        path = Path(project) / REQUIREMENTS_NAME
        if not path.is_file():
            raise UserInputError(f"{project}: no {REQUIREMENTS_NAME} there")
        return path
    folders = [p for run in reversed(runs)
               for p in ([run.folder] + sorted(q for q in run.folder.iterdir() if q.is_dir()))]
    for folder in folders:
        record = _read_json(folder / "record.json")
        campaign = record.get("campaign") if isinstance(record, dict) else None
        if isinstance(campaign, str) and (Path(campaign) / REQUIREMENTS_NAME).is_file():
            return Path(campaign) / REQUIREMENTS_NAME
    for folder in folders:
        if (folder / "inputs" / REQUIREMENTS_NAME).is_file():
            return folder / "inputs" / REQUIREMENTS_NAME
    return None


def requirement_matrix(run_dirs: list[Path], project: Path | None = None) -> Matrix:
    """The matrix of ``run_dirs`` (in the order of their start)."""
    runs = sorted((read_run(Path(d)) for d in run_dirs), key=lambda r: (r.start, str(r.folder)))
    source = _requirements_file(runs, project)
    listed: list[Requirement] = []
    problems: list[str] = []
    if source is not None:
        listed, bad_rows = read_requirements(source)
        problems = [row_error_line(source, e) for e in bad_rows]
    known = {r.id for r in listed}
    unlisted = sorted({rid for run in runs for rid in run.results} - known)
    return Matrix(listed, runs, source, unlisted, problems)


# ---------------------------------------------------------------------------- outputs
def _run_name(run: MatrixRun) -> str:
    return run.folder.name


def matrix_csv(matrix: Matrix) -> str:
    """One row per requirement: id, text, method, then one column per run (its folder's
    name): passed, failed or not run."""
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(["id", "text", "method", *(_run_name(r) for r in matrix.runs)])
    rows = [(r.id, r.text, r.method) for r in matrix.requirements] + \
        [(rid, "", "(not in requirements.csv)") for rid in matrix.unlisted]
    for rid, text, method in rows:
        writer.writerow([rid, text, method, *(matrix.cell(run, rid) for run in matrix.runs)])
    return out.getvalue()


_CELL = {PASSED: "passed", FAILED: "failed", NOT_RUN: "notrun"}


def matrix_html(matrix: Matrix) -> str:
    """The matrix as one self-contained page (inline CSS; no script, no link)."""
    from seqrun import __version__
    from seqrun.report.html import CSS

    head = "".join(
        f'<th class="run" title="{escape(str(run.folder))}">{escape(_run_name(run))}<br>'
        f'<span class="note">{escape(run.sequence)} · {escape(run.start[:19])} · '
        f"{escape(run.status)}</span></th>" for run in matrix.runs)
    rows = []
    listed = [(r.id, r.text, r.method, False) for r in matrix.requirements] + \
        [(rid, "", "", True) for rid in matrix.unlisted]
    for rid, text, method, unlisted in listed:
        cells = "".join(
            f'<td class="cell {_CELL[matrix.cell(run, rid)]}" data-requirement="{escape(rid)}" '
            f'data-run="{escape(_run_name(run))}">{escape(matrix.cell(run, rid))}</td>'
            for run in matrix.runs)
        note = ' <span class="note">(not in requirements.csv)</span>' if unlisted else ""
        rows.append(f'<tr id="req-{escape(rid)}"><td class="mono">{escape(rid)}{note}</td>'
                    f"<td>{escape(text)}</td><td>{escape(method)}</td>{cells}</tr>")
    source = (f"Requirements from <span class=\"mono\">{escape(str(matrix.source))}</span>."
              if matrix.source is not None else
              f"No {REQUIREMENTS_NAME} found: only the requirements the runs verified.")
    problems = "".join(f'<li class="mono">{escape(p)}</li>' for p in matrix.problems)
    now = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    css = CSS + """
td.cell{text-align:center;font-weight:600}
td.passed{background:#e3f4e3;color:#1b6e1b}td.failed{background:#fdecea;color:#a31515}
td.notrun{color:#888}th.run{font-weight:600;font-size:12px}
"""
    return "\n".join((
        "<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
        "<title>Requirement matrix</title>", f"<style>{css}</style></head><body>",
        "<h1>Requirement matrix</h1>",
        f"<p>{len(matrix.ids())} requirement(s) × {len(matrix.runs)} run(s). {source} "
        "A requirement is <em>passed</em> in a run when every step that verifies it passed, "
        "<em>failed</em> when one failed, <em>not run</em> otherwise.</p>",
        f"<ul>{problems}</ul>" if problems else "",
        '<table id="matrix"><tr><th>requirement</th><th>text</th><th>method</th>'
        f"{head}</tr>{''.join(rows)}</table>",
        f'<p class="note">Written by seqrun {escape(__version__)} at {escape(now)}.</p>',
        "</body></html>")) + "\n"
