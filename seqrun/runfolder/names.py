"""The names of the files a run folder holds, for the run log that writes them and every
reader (the report, ``seqrun runs``, tests)."""

from __future__ import annotations

from pathlib import Path

#: The CAN trace of a run; older versions wrote it uncompressed (the second name).
TRACE_NAME = "trace.log.gz"
TRACE_NAMES = (TRACE_NAME, "trace.log")


def trace_path(folder: Path) -> Path | None:
    """The run folder's CAN trace (compressed, or an older run's plain one), if any."""
    return next((Path(folder) / name for name in TRACE_NAMES
                 if (Path(folder) / name).is_file()), None)


#: The run's events, one JSON line each, gzip-compressed (``zcat events.jsonl.gz | jq``);
#: older versions wrote them uncompressed (the second name).
EVENTS_NAME = "events.jsonl.gz"
EVENTS_NAMES = (EVENTS_NAME, "events.jsonl")


def events_path(folder: Path) -> Path | None:
    """The run folder's event log (compressed, or an older run's plain one), if any."""
    return next((Path(folder) / name for name in EVENTS_NAMES
                 if (Path(folder) / name).is_file()), None)
