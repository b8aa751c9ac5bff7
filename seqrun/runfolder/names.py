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


#: The copy of the suite file a suite's folder holds (written when the folder is made):
#: what tells a suite's folder, whose runs are its subfolders, from a run's.
SUITE_NAME = "suite.yaml"


def is_suite_folder(folder: Path) -> bool:
    """A suite's folder (docs/suites.md): its runs are its subfolders."""
    return (folder / SUITE_NAME).is_file() and not (folder / "report.json").exists()


def runs_of_suite(folder: Path) -> list[Path]:
    """The subfolders of a suite's folder, in the order the suite ran them."""
    return sorted(p for p in folder.iterdir() if p.is_dir())
