"""``seqrun validate DIR`` (or several files): every sequence of a campaign, one table.

Each sequence gets the static checks and the dry run (``--static``: the checks only), each
pose file the pose checks against the arm; then one summary table: file, result, simulated
duration, lowest guard clearance, findings. ``--json`` prints the same as one object,
``--junit FILE`` writes a JUnit report for CI (and its CTRF JSON beside it,
``FILE``'s name with ``.ctrf.json``). Exit 0 only when everything is valid; 1 when a file
is not; 3 when every file is valid but a rehearsed ``--sim-fault`` aborted a dry run (as
``seqrun run`` exits; README "Exit codes"). The
checks are the service's (:mod:`seqrun.service.campaign_checks`); this prints them.
The pre-commit hook (``.pre-commit-hooks.yaml``) runs ``seqrun validate --static`` on the
changed sequence and pose files.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

import typer

if TYPE_CHECKING:
    from seqrun.service.campaign_checks import FileResult

def table(results: list[FileResult]) -> str:
    rows = [("file", "result", "simulated", "lowest guard clearance", "findings")]
    for r in results:
        clearance = "-" if r.clearance_mm is None else f"{r.clearance_mm:.1f} mm ({r.clearance_at})"
        findings = f"{len(r.errors)} error{'s' * (len(r.errors) != 1)}"
        if r.notes:
            findings += f", {len(r.notes)} note{'s' * (len(r.notes) != 1)}"
        rows.append((r.file, r.result, "-" if r.simulated_s is None else f"{r.simulated_s:.2f} s",
                     clearance, findings))
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip() for row in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    bad = sum(not r.valid for r in results)
    lines.append(f"{len(results)} file{'s' * (len(results) != 1)}: "
                 + ("all valid" if not bad else f"{bad} not valid"))
    return "\n".join(lines)


def junit(results: list[FileResult]) -> str:
    """The JUnit report: a test case per file, valid against Jenkins xunit's junit-10.xsd
    (``errors`` on the suite; no ``file`` on a test case: its name is the file)."""
    # (imported here: xml.sax.saxutils pulls in urllib, http and email, which a single
    # file's validation does not need)
    from xml.sax.saxutils import escape, quoteattr

    failures = sum(not r.valid for r in results)
    total = sum(r.simulated_s or 0.0 for r in results)
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             f'<testsuites><testsuite name="seqrun validate" tests="{len(results)}" '
             f'failures="{failures}" errors="0" time="{total:.3f}">']
    for r in results:
        lines.append(f'  <testcase classname={quoteattr(r.kind)} name={quoteattr(r.file)} '
                     f'time="{r.simulated_s or 0.0:.3f}">')
        if not r.valid:
            text = "\n".join(r.errors) or r.result
            lines.append(f'    <failure message={quoteattr(r.result)}>{escape(text)}</failure>')
        if r.notes:
            lines.append(f"    <system-out>{escape(chr(10).join(r.notes))}</system-out>")
        lines.append("  </testcase>")
    lines.append("</testsuite></testsuites>")
    return "\n".join(lines) + "\n"


def ctrf(results: list[FileResult], start_s: float, stop_s: float) -> str:
    """The same as CTRF JSON (seqrun/runfolder/ctrf.py), written beside the JUnit file."""
    from seqrun import __version__
    from seqrun.runfolder.ctrf import ctrf_report, ctrf_test

    tests = [ctrf_test(r.file, "passed" if r.valid else "failed", r.simulated_s,
                       suite="seqrun validate", location=r.file,
                       message=None if r.valid else ("\n".join(r.errors) or r.result),
                       extra={"kind": r.kind, "result": r.result,
                              **({"notes": list(r.notes)} if r.notes else {})})
             for r in results]
    return ctrf_report(tests, start_s=start_s, stop_s=stop_s, version=__version__)


def report(results: list[FileResult], *, as_json: bool, junit_file: Path | None,
           began_s: float | None = None) -> bool:
    """Print the summary (and write the JUnit file); True when every file is valid."""
    valid = all(r.valid for r in results)
    if junit_file is not None:
        import time

        from seqrun.runfolder.ctrf import ctrf_path

        junit_file.parent.mkdir(parents=True, exist_ok=True)
        junit_file.write_text(junit(results), encoding="utf-8")
        stop = time.time()
        ctrf_path(junit_file).write_text(
            ctrf(results, stop if began_s is None else began_s, stop), encoding="utf-8")
    if as_json:
        typer.echo(json.dumps({"valid": valid, "results": [r.as_dict() for r in results]},
                              indent=2, ensure_ascii=False))
        return valid
    for r in results:
        for line in r.errors:
            typer.echo(line)
        for line in r.notes:
            typer.echo(line)
    typer.echo(table(results))
    return valid
