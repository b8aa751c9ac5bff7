"""Requirements: a campaign's ``requirements.csv`` and what runs say of each requirement.

A step may name the requirements it verifies (``verifies: [REQ-…]``); report.json keeps
them per step and sums them up per run (:func:`requirement_results`). The campaign lists
its requirements in ``requirements.csv`` beside seqrun.toml (columns ``id,text,method``),
read here with the csv module; each malformed row is one ``requirements.csv:LINE:
message`` line. Pure but for reading that one file.
"""

from __future__ import annotations

import csv
import io
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

#: The file's name, at the campaign root beside seqrun.toml.
REQUIREMENTS_NAME = "requirements.csv"
#: Its columns, in this order (a header row names them).
COLUMNS = ("id", "text", "method")
#: What a requirement id may be (as a step's ``verifies`` says it).
ID_RE = re.compile(r"^[A-Za-z0-9_.:-]{1,64}$")

PASSED, FAILED, NOT_RUN = "passed", "failed", "not run"


@dataclass(frozen=True)
class Requirement:
    id: str
    text: str
    method: str
    line: int


#: A malformed row: its line and what is wrong.
RowError = tuple[int, str]


def read_requirements(path: Path) -> tuple[list[Requirement], list[RowError]]:
    """The requirements of ``path`` in file order, and ``(line, message)`` per malformed
    row (a row with a bad or repeated id is left out; the rest are kept); say each as
    :func:`row_error_line` does."""
    try:
        text = Path(path).read_text(encoding="utf-8-sig")
    except OSError as exc:
        return [], [(1, f"cannot be read ({exc.strerror or exc})")]
    except UnicodeDecodeError:
        return [], [(1, "not UTF-8 text")]
    return parse_requirements(text)


def row_error_line(path: Path | str, error: RowError) -> str:
    """``requirements.csv:LINE: message``."""
    return f"{path}:{error[0]}: {error[1]}"


def parse_requirements(text: str) -> tuple[list[Requirement], list[RowError]]:
    """:func:`read_requirements` of the file's text."""
    reader = csv.reader(io.StringIO(text, newline=""))
    found: list[Requirement] = []
    errors: list[RowError] = []
    seen: dict[str, int] = {}
    header_done = False
    try:
        for row in reader:
            line = reader.line_num
            if not row or all(not cell.strip() for cell in row):
                continue
            cells = [cell.strip() for cell in row]
            if not header_done:
                header_done = True
                if [c.lower() for c in cells] != list(COLUMNS):
                    errors.append((line, f"the first row must name the columns "
                                  f"{','.join(COLUMNS)} (got {','.join(cells)})"))
                    return [], errors
                continue
            if len(cells) != len(COLUMNS):
                errors.append((line, f"{len(cells)} column(s), expected "
                              f"{len(COLUMNS)} ({','.join(COLUMNS)})"))
                continue
            rid, what, method = cells
            if not ID_RE.match(rid):
                errors.append((line, f"'{rid}' is not a requirement id (1 to 64 "
                              "letters, digits, _ . : -)"))
            elif rid in seen:
                errors.append((line, f"'{rid}' is listed already (line {seen[rid]})"))
            else:
                seen[rid] = line
                found.append(Requirement(rid, what, method, line))
    except csv.Error as exc:
        errors.append((reader.line_num, str(exc)))
    if not header_done:
        errors.append((1, "empty: the first row must name the columns "
                      f"{','.join(COLUMNS)}"))
    return found, errors


def campaign_requirements(root: Path | None) -> Path | None:
    """The campaign's requirements.csv, if it has one."""
    if root is None:
        return None
    path = Path(root) / REQUIREMENTS_NAME
    return path if path.is_file() else None


def step_ids(step: Mapping[str, Any], key: str = "verifies") -> list[str]:
    """A reported step's ``verifies`` (or ``tags``): a list of text, else none (a run
    folder of an older version, or a value that is not one)."""
    value = step.get(key)
    return [v for v in value if isinstance(v, str)] if isinstance(value, list) else []


def requirement_results(steps: Iterable[Mapping[str, Any]]) -> dict[str, str]:
    """``{id: passed | failed | not run}`` of the steps' ``verifies`` (report.json's step
    dicts): failed when a step that verifies it failed; passed when every step that
    verifies it passed; else not run (none ran, or some did not: an abort, a step after
    the fault)."""
    seen: dict[str, list[str]] = {}
    for step in steps:
        for rid in step_ids(step):
            seen.setdefault(rid, []).append(str(step.get("status")))
    out: dict[str, str] = {}
    for rid, statuses in seen.items():
        if "failed" in statuses:
            out[rid] = FAILED
        elif all(s == "passed" for s in statuses):
            out[rid] = PASSED
        else:
            out[rid] = NOT_RUN
    return out


def run_requirements(report: Mapping[str, Any]) -> dict[str, str]:
    """What a run's report.json says of each requirement it verified: its ``requirements``
    summary, else worked out from its steps; ``{}`` for a run of an older version."""
    summary = report.get("requirements")
    if isinstance(summary, dict):
        return {str(k): v for k, v in summary.items() if v in (PASSED, FAILED, NOT_RUN)}
    steps = report.get("steps")
    return requirement_results(s for s in steps if isinstance(s, dict)) \
        if isinstance(steps, list) else {}
