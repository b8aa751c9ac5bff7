"""Whether a finished run folder is whole and its inputs are as the run used them.

A full disk (or a pulled stick) stops a run-folder file where it was and the run goes on
(``seqrun/runfolder/logfile.py``): report.json may still say ``passed`` of a run whose
events, trace and run.mcap stop mid-run. And ``inputs/`` is a copy anyone can edit after
the run. ``seqrun runs`` and ``seqrun report`` read this module's verdict so that neither
passes such a folder off as a plain, whole run:

- :func:`incomplete`: what is cut short or lacks its end - ``log_errors`` in report.json
  (the run knew), events.jsonl without ``run_finished`` as its last line (or with a torn
  one), a trace that ends at a sync flush instead of gzip's end (``thorough``: decompressed
  to its end), run.mcap without MCAP's closing magic or a ``run.mcap.partial/`` left, an
  unreadable record.json. Of a run of several arms' folder (``arms.json``), its run.mcap
  (each arm's part is a run folder of its own).
- :func:`changed_inputs`: every ``inputs/`` file whose sha256 is not record.json's, that is
  missing, or that record.json does not list (added afterwards).

Only reads; one line per finding, naming the file.
"""

from __future__ import annotations

import hashlib
import json
import zlib
from pathlib import Path
from typing import Any

from seqrun.runfolder.names import EVENTS_NAME, events_path, trace_path

__all__ = ["changed_inputs", "incomplete"]

#: The last bytes of every whole MCAP file (its magic, written after the footer).
MCAP_MAGIC = b"\x89MCAP0\r\n"
#: The end of a deflate sync flush: a gzip trace cut back to its last flush ends so.
SYNC_FLUSH_END = b"\x00\x00\xff\xff"
#: How much of the events' end is read to find their last line.
TAIL_BYTES = 64 * 1024
_CHUNK = 1 << 16


def _json(path: Path) -> tuple[Any, bool]:
    """``(data, readable)``; a missing file is ``(None, True)``."""
    if not path.is_file():
        return None, True
    try:
        return json.loads(path.read_text(encoding="utf-8")), True
    except (OSError, ValueError, RecursionError):
        return None, False


def incomplete(folder: Path, *, thorough: bool = False) -> list[str]:
    """What of a finished run's folder is cut short or lacks its end (empty: whole). A run
    still running (report.json says so) or refused before it started is not judged by its
    log. ``thorough``: decompress the trace to its end (``seqrun report``; the listing
    reads only the files' ends)."""
    folder = Path(folder)
    if (folder / "arms.json").is_file() and not (folder / "report.json").exists():
        return _mcap(folder)   # a run of several arms: each arm's part is a run folder
    found: list[str] = []
    report, _ = _json(folder / "report.json")
    record, record_readable = _json(folder / "record.json")
    if not record_readable:
        found.append("record.json: unreadable (cut short?)")
    if not isinstance(report, dict) or report.get("status") == "running":
        return found   # (no report to judge by: listed as corrupted, or running)
    for error in (report.get("log_errors") or [])[:1]:
        more = len(report["log_errors"]) - 1
        found.append(f"the run could not write its whole log: {str(error)[:200]}"
                     + (f" (and {more} more)" if more > 0 else ""))
    if report.get("nothing_sent"):
        return found   # refused or ended before it started: no log to judge
    events = events_path(folder)
    if events is None:
        found.append(f"{EVENTS_NAME}: missing")
    elif events.suffix == ".gz":
        # Cheap: where the gzip stream ends; thorough: its last line, decompressed.
        why = _gzip_end(events, thorough)
        if why is None and thorough:
            why = _last_event(_gzip_tail(events))
        if why:
            found.append(f"{events.name}: {why}")
    else:   # an older run's plain events.jsonl
        why = _last_event(_tail(events))
        if why:
            found.append(f"{events.name}: {why}")
    trace = trace_path(folder)
    if trace is not None and trace.suffix == ".gz":
        why = _gzip_end(trace, thorough)
        if why:
            found.append(f"{trace.name}: {why}")
    found += _mcap(folder)
    return found


def _tail(path: Path) -> bytes:
    size = path.stat().st_size
    with open(path, "rb") as f:
        f.seek(max(0, size - TAIL_BYTES))
        return f.read()


def _gzip_tail(path: Path) -> bytes:
    """The last TAIL_BYTES of a gzip file's text, decompressed as a stream (what a cut
    file holds up to its cut)."""
    decompressor, tail = zlib.decompressobj(31), b""
    with open(path, "rb") as f:
        while chunk := f.read(_CHUNK):
            try:
                tail = (tail + decompressor.decompress(chunk))[-TAIL_BYTES:]
            except zlib.error:
                break
            if decompressor.eof:   # another member follows (appended): read it too
                rest = decompressor.unused_data
                decompressor = zlib.decompressobj(31)
                if rest:
                    tail = (tail + decompressor.decompress(rest))[-TAIL_BYTES:]
    return tail


def _last_event(tail: bytes) -> str | None:
    """Why the events' text (its last bytes) does not end with the run's end marker."""
    if not tail:
        return "empty"
    if not tail.endswith(b"\n"):
        return "its last line is cut short"
    last = tail.rstrip(b"\n").rsplit(b"\n", 1)[-1]
    try:
        event = json.loads(last)
    except ValueError:
        return "its last line is not an event (cut short?)"
    if not isinstance(event, dict) or event.get("type") != "run_finished":
        at = event.get("t") if isinstance(event, dict) else None
        return ("no run_finished (the end marker): the log stops"
                + (f" at t = {at} s" if isinstance(at, (int, float)) else ""))
    return None


def _gzip_end(path: Path, thorough: bool) -> str | None:
    """Why a gzip trace is not whole, or None. Cheap: its last bytes (a trace cut back to
    a flush ends with a sync flush, a closed one with gzip's trailer); thorough: every
    member decompressed to its end."""
    size = path.stat().st_size
    if size == 0:
        return "empty"
    if not thorough:
        with open(path, "rb") as f:
            f.seek(max(0, size - len(SYNC_FLUSH_END)))
            end = f.read()
        return "cut short (it ends at a flush, not at gzip's end)" \
            if end == SYNC_FLUSH_END else None
    decompressor, in_member = zlib.decompressobj(31), False
    with open(path, "rb") as f:
        while chunk := f.read(_CHUNK):
            while chunk:   # (the output is dropped: only where the stream ends matters)
                in_member = True
                try:
                    decompressor.decompress(chunk)
                except zlib.error as exc:
                    return f"unreadable ({exc})"
                if not decompressor.eof:
                    break
                chunk = decompressor.unused_data   # a next member may follow
                decompressor, in_member = zlib.decompressobj(31), False
    return "cut short (its compressed stream does not end)" if in_member else None


def _mcap(folder: Path) -> list[str]:
    found = []
    if (folder / "run.mcap.partial").exists():
        found.append("run.mcap: not ended (run.mcap.partial/ holds what was written)")
    bag = folder / "run.mcap"
    if bag.is_file():
        size = bag.stat().st_size
        with open(bag, "rb") as f:
            head = f.read(len(MCAP_MAGIC))
            f.seek(max(0, size - len(MCAP_MAGIC)))
            end = f.read()
        if head != MCAP_MAGIC or end != MCAP_MAGIC or size < 2 * len(MCAP_MAGIC):
            found.append("run.mcap: cut short (no MCAP end)")
    return found


def changed_inputs(folder: Path) -> list[str]:
    """Every file of ``inputs/`` that is not as record.json recorded it: changed (its
    sha256 differs), missing, or not listed (added afterwards). Empty: as the run used
    them, or no record to check against (an older run)."""
    folder = Path(folder)
    record, _ = _json(folder / "record.json")
    if not isinstance(record, dict) or not isinstance(record.get("inputs"), list):
        return []
    found, listed = [], set()
    for item in record["inputs"]:
        if not isinstance(item, dict) or not isinstance(item.get("copy"), str):
            continue
        copy = folder / item["copy"]
        listed.add(copy.resolve())
        try:
            digest = hashlib.sha256(copy.read_bytes()).hexdigest()
        except OSError:
            found.append(f"{item['copy']}: missing")
            continue
        if digest != item.get("sha256"):
            found.append(f"{item['copy']}: changed (its sha256 is not record.json's)")
    inputs = folder / "inputs"
    if inputs.is_dir():
        for path in sorted(p for p in inputs.rglob("*") if p.is_file()):
            if path.resolve() not in listed:
                found.append(f"{path.relative_to(folder).as_posix()}: added (not in "
                             "record.json)")
    return found
