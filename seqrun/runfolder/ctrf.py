"""CTRF (Common Test Report Format, ctrf.io): the JSON test report written beside every
junit.xml, for CI tools that read CTRF rather than JUnit. Pure: dicts and text, no I/O.

A report is ``{"reportFormat": "CTRF", "specVersion", "results": {"tool", "summary",
"tests"}}``; each test has ``name``, ``status`` (passed, failed, skipped, pending, other)
and ``duration`` (ms); the summary counts them and gives ``start``/``stop`` (ms since the
epoch).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

__all__ = ["CTRF_STATUSES", "ctrf_path", "ctrf_report", "ctrf_test", "location_fields"]

#: The statuses CTRF knows.
CTRF_STATUSES = ("passed", "failed", "skipped", "pending", "other")
#: The CTRF specification version written (SemVer, as the format asks).
SPEC_VERSION = "0.0.0"
#: seqrun's step statuses in CTRF's words (aborted: the run stopped in that step).
_STATUS = {"passed": "passed", "failed": "failed", "aborted": "failed",
           "skipped": "skipped", "pending": "pending"}


def ctrf_path(junit: Path) -> Path:
    """Where the CTRF report of ``junit`` goes: beside it, ``junit.xml`` -> ``junit.ctrf.json``."""
    junit = Path(junit)
    return junit.with_name(f"{junit.stem}.ctrf.json")


def location_fields(location: str) -> dict[str, Any]:
    """``filePath`` and ``line`` of a ``file:line:col`` location (a step's)."""
    parts = location.rsplit(":", 2)
    if len(parts) == 3 and parts[1].isdigit():
        return {"filePath": parts[0], "line": int(parts[1])}
    return {"filePath": location} if location else {}


def ctrf_test(name: str, status: str, duration_s: float | None, *, suite: str | None = None,
              message: str | None = None, location: str = "",
              extra: dict[str, Any] | None = None) -> dict[str, Any]:
    """One test: ``status`` in seqrun's words (passed, failed, aborted, skipped, pending) or
    CTRF's; anything else is ``other``."""
    test: dict[str, Any] = {"name": name, "status": _STATUS.get(status, "other"),
                            "duration": int(round((duration_s or 0.0) * 1000))}
    if suite:
        test["suite"] = suite
    if message:
        test["message"] = message
    test.update(location_fields(location))
    if status not in _STATUS:
        test["rawStatus"] = status
    if extra:
        test["extra"] = extra
    return test


def ctrf_report(tests: list[dict[str, Any]], *, start_s: float, stop_s: float,
                tool: str = "seqrun", version: str | None = None,
                extra: dict[str, Any] | None = None) -> str:
    """The report (JSON text) of ``tests`` (:func:`ctrf_test`), run from ``start_s`` to
    ``stop_s`` (seconds since the epoch)."""
    summary: dict[str, Any] = {"tests": len(tests)}
    for status in CTRF_STATUSES:
        summary[status] = sum(1 for t in tests if t["status"] == status)
    summary["start"] = int(round(start_s * 1000))
    summary["stop"] = int(round(stop_s * 1000))
    tool_fields: dict[str, Any] = {"name": tool}
    if version:
        tool_fields["version"] = version
    results: dict[str, Any] = {"tool": tool_fields, "summary": summary, "tests": tests}
    if extra:
        results["extra"] = extra
    return json.dumps({"reportFormat": "CTRF", "specVersion": SPEC_VERSION,
                       "results": results}, indent=2, ensure_ascii=False) + "\n"
