"""What a run left in its folder, read as written: report.json, steps.jsonl, events.jsonl,
the CAN trace (trace.log.gz; trace.log of older runs) (the tests' one reader of a run
folder)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import can

from seqrun.runfolder.logfile import read_lines
from seqrun.runfolder.names import events_path, trace_path
from seqrun.service.runlog import read_trace, trace_text


@dataclass(frozen=True)
class RunFolder:
    """Each read goes to the files again, so a test may read, change a file and read anew."""

    path: Path

    def report(self) -> dict:
        """report.json as written (``seqrun.service.runlog.read_report`` also fills in a killed run)."""
        return json.loads((self.path / "report.json").read_text(encoding="utf-8"))

    def steps(self) -> list[dict]:
        return _json_lines(self.path / "steps.jsonl")

    def events(self, type: str | None = None, *, live: bool = False) -> list[dict]:
        """The events in order; with ``type``, only those of that type. ``live``: the run
        may still be writing (no file yet: none; a line being written ends the list)."""
        path = events_path(self.path)   # events.jsonl.gz (older runs: events.jsonl)
        if path is None:
            assert live, f"no events in {self.path}"
            return []
        events = _json_lines(path, live=live)
        return events if type is None else [e for e in events if e["type"] == type]

    def trace(self) -> list[can.Message]:
        """The frames of the trace, stamped on the run's clock."""
        return read_trace(self.path, run_clock=True)

    def trace_frames(self) -> list[can.Message]:
        """The frames as python-can's own reader reads the file (wall-clock stamps)."""
        path = self.trace_path()
        assert path is not None, f"no trace in {self.path}"
        return list(can.LogReader(str(path)))

    def trace_path(self) -> Path | None:
        """The trace file, None when the run wrote none (nothing was sent)."""
        return trace_path(self.path)

    def trace_text(self) -> str:
        """The trace's candump lines as text (whole lines, however the file ends)."""
        return trace_text(self.path)

    def trace_lines(self) -> list[str]:
        return [line for line in self.trace_text().splitlines() if line]


def _json_lines(path: Path, *, live: bool = False) -> list[dict]:
    out = []
    if path.suffix == ".gz":   # whatever decodes (a file being written: its flushed part)
        lines = [raw.decode("utf-8") for raw in read_lines(path)]
    else:
        lines = path.read_text(encoding="utf-8").splitlines()
    for line in lines:
        try:
            out.append(json.loads(line))
        except json.JSONDecodeError:
            if not live:
                raise
            break  # the line being written
    return out
