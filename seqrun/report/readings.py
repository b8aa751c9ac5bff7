"""events.jsonl as a stream: the arm's readings in chunks, every other event as it comes.

A run at 100 Hz writes 360,000 readings an hour (``setpoint`` events of streamed cycles,
``measurement`` events of monitoring); the report never holds them all. :func:`split`
passes every other event on as its dict and gathers the readings into :class:`Series`
chunks of full resolution (at most :data:`CHUNK_READINGS` each), with the windowed
measured velocity (:mod:`seqrun.arm.tracking`) estimated across chunk boundaries exactly
as over the whole series. Readings come in the order the run wrote them (time order).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable, Iterator

import numpy as np

from seqrun.arm.tracking import VelocityStream, sample_time
from seqrun.runfolder.logfile import read_lines

#: Event types that carry one reading of the whole arm.
SAMPLE_EVENTS = ("setpoint", "measurement")
#: Readings per chunk: large enough for numpy to pay off, small enough to stay flat.
CHUNK_READINGS = 1024


@dataclass
class Series:
    """Readings of the arm in time order (samples × joints, degrees, deg/s).

    ``planned`` and ``planned_vel`` are NaN where no plan was streamed (waits, checkpoints);
    ``state`` is the short state byte of each module (-1 where the log has none);
    ``measured_vel`` is the windowed estimate of :mod:`seqrun.arm.tracking`.
    """

    t: np.ndarray
    step: np.ndarray
    streamed: np.ndarray          # True for setpoint samples (a plan was being streamed)
    planned: np.ndarray
    measured: np.ndarray
    planned_vel: np.ndarray
    measured_vel: np.ndarray
    state: np.ndarray
    #: Each joint's own sample time (samples × joints): ``t`` unless the joints of a
    #: reading answered apart (``read_t`` per joint).
    t_joint: np.ndarray

    def __len__(self) -> int:
        return len(self.t)

    @classmethod
    def empty(cls, dof: int) -> Series:
        nothing = np.zeros((0, dof))
        return cls(np.zeros(0), np.zeros(0, int), np.zeros(0, bool), nothing, nothing,
                   nothing, nothing, np.zeros((0, dof), int), nothing)

    @classmethod
    def concatenate(cls, chunks: list[Series], dof: int) -> Series:
        if not chunks:
            return cls.empty(dof)
        return cls(*(np.concatenate([getattr(c, f) for c in chunks])
                     for f in cls.__dataclass_fields__))


class EventLines:
    """The events of an events.jsonl file, one dict per parseable line; ``torn`` counts
    the lines that were not (a run killed mid-line). Iterating reads the file anew."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self.torn = 0

    def __iter__(self) -> Iterator[dict]:
        self.torn = 0
        if self.path.suffix == ".gz":   # events.jsonl.gz: what decodes, whole lines
            for raw in read_lines(self.path):
                event = self._parse(raw.decode("utf-8", errors="replace"))
                if event is not None:
                    yield event
            return
        with open(self.path, encoding="utf-8", errors="replace") as f:
            for line in f:
                event = self._parse(line)
                if event is not None:
                    yield event

    def _parse(self, line: str) -> dict | None:
        if not line.strip():
            return None
        try:
            event = json.loads(line)
        except json.JSONDecodeError:
            self.torn += 1
            return None
        return event if isinstance(event, dict) and "type" in event else None


def joints_of(event: dict) -> list:
    """The measured joints of a reading (``measured_deg`` of a cycle, ``joints_deg`` of a
    monitoring reading)."""
    value = event.get("measured_deg", event.get("joints_deg"))
    return value if isinstance(value, list) else []


class Chunker:
    """Readings in, :class:`Series` chunks out (with the measured velocity)."""

    def __init__(self, dof: int, window_s: float, size: int | None = None) -> None:
        self.dof = dof
        self.size = size or CHUNK_READINGS
        self.velocity = VelocityStream(window_s)
        self._rows: list[dict] = []

    def accepts(self, event: dict) -> bool:
        """A reading with a full set of joints (another version's or a hand-edited line is
        left out rather than failing the whole report)."""
        return (isinstance(event.get("t"), (int, float)) and len(joints_of(event)) == self.dof
                and (event["type"] != "setpoint"
                     or len(event.get("planned_deg") or ()) == self.dof))

    def add(self, event: dict) -> Series | None:
        """Take one reading; a full chunk when there is one."""
        if not self.accepts(event):
            return None
        self._rows.append(event)
        return self.flush() if len(self._rows) >= self.size else None

    def flush(self) -> Series | None:
        """The readings taken since the last chunk, as a chunk (None: there are none)."""
        rows, self._rows = self._rows, []
        if not rows:
            return None
        n, dof = len(rows), self.dof
        # a reading's time is when the joints answered (read_t: one, or one per joint),
        # where the log has it; else when it was logged
        t = np.empty(n)
        t_joint = np.empty((n, dof))
        for i, e in enumerate(rows):
            read_t = e.get("read_t")
            if isinstance(read_t, list) and len(read_t) == dof:
                t[i] = sample_time(read_t)
                t_joint[i] = read_t
            else:
                t[i] = read_t if isinstance(read_t, (int, float)) else e["t"]
                t_joint[i] = t[i]
        step = np.array([e.get("step") or 0 for e in rows], dtype=int)
        measured = np.array([joints_of(e) for e in rows], dtype=float)
        streamed = np.array([e["type"] == "setpoint" for e in rows], dtype=bool)
        planned = np.full((n, dof), np.nan)
        planned_vel = np.full((n, dof), np.nan)
        state = np.full((n, dof), -1, int)
        _fill(planned, rows, lambda e: e["planned_deg"] if e["type"] == "setpoint" else None)
        _fill(planned_vel, rows, lambda e: e.get("planned_vel_deg_s")
              if e["type"] == "setpoint" else None)
        _fill(state, rows, lambda e: e.get("state"))
        if np.any(np.diff(t) < 0):   # a log written out of order: this chunk in time order
            order = np.argsort(t, kind="stable")
            t, step, streamed, planned, measured, planned_vel, state, t_joint = (
                a[order] for a in (t, step, streamed, planned, measured, planned_vel, state,
                                   t_joint))
        measured_vel = self.velocity.feed(t, measured, t_joint)
        return Series(t, step, streamed, planned, measured, planned_vel, measured_vel, state,
                      t_joint)


def _fill(target: np.ndarray, rows: list[dict], value: Callable[[dict], list | None]) -> None:
    """target[i] = value(rows[i]) where that is a full row of joints."""
    dof = target.shape[1]
    index, values = [], []
    for i, e in enumerate(rows):
        v = value(e)
        if isinstance(v, list) and len(v) == dof:
            index.append(i)
            values.append(v)
    if index:
        target[index] = np.array(values, dtype=target.dtype)


def split(events: Iterable[dict], *, dof: Callable[[], int | None],
          window_s: Callable[[], float], size: int | None = None
          ) -> Iterator[dict | Series]:
    """Every event that is not a reading, as it comes; the readings as chunks.

    ``dof`` and ``window_s`` are asked at the first reading (after the events before it
    have been handed on: ``run_started`` tells the arm); ``dof`` None: the number of
    joints of the first reading that has some. ``size``: readings per chunk (default
    :data:`CHUNK_READINGS`).
    """
    chunker: Chunker | None = None
    for event in events:
        if event.get("type") not in SAMPLE_EVENTS:
            yield event
            continue
        if chunker is None:
            n = dof() or len(joints_of(event))
            if not n:
                continue
            chunker = Chunker(n, window_s(), size or CHUNK_READINGS)
        chunk = chunker.add(event)
        if chunk is not None:
            yield chunk
    if chunker is not None:
        chunk = chunker.flush()
        if chunk is not None:
            yield chunk
