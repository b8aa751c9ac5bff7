"""Min/max envelopes of long lines, built a chunk at a time in bounded memory (pure).

A plot of an hour at 100 Hz has 360,000 points per line; the page shows a few thousand.
:class:`Envelope` keeps, for each bucket of time, the lowest and the highest value of
every line (with the sample's time), so a spike of one sample survives, and a bucket
whose values are all NaN keeps one NaN point, so a gap stays a gap.

Lines of at most ``max_points`` samples are kept whole. Beyond, buckets are spans of time
``2**level`` ms wide from the first sample, at the finest level that needs at most
``max_points // 2`` buckets (two points each): when the run outgrows a level, neighbouring
buckets merge (twice as wide), so memory never grows with the run. Bucket edges depend only
on the samples' times, never on how they were chunked: the envelope of a run is the same
whichever way it was read.
"""

from __future__ import annotations

import numpy as np

#: Width of the buckets at level 0 (s).
BASE_WIDTH_S = 1e-3

#: Bucket arrays: the first sample's index and time; per line, the index, time and value
#: of the lowest (lo) and the highest (hi) sample. lo_y is NaN where every value was NaN.
_FIELDS = ("first_i", "first_t", "lo_i", "lo_t", "lo_y", "hi_i", "hi_t", "hi_y")


class Envelope:
    """The envelope of ``lines`` lines sampled at the same times."""

    def __init__(self, lines: int, max_points: int) -> None:
        self.lines = int(lines)
        self.max_points = max(2, int(max_points))
        self.buckets = self.max_points // 2
        self.count = 0                  # samples added
        self.level: int | None = None   # None: every sample kept (a short line)
        self._t0 = 0.0
        self._raw: list[tuple[np.ndarray, np.ndarray]] = []   # a short line's samples
        self._b = _as_buckets(0, np.zeros(0), np.zeros((0, self.lines)))
        self._ids = np.zeros(0, np.int64)

    def add(self, t: np.ndarray, y: np.ndarray) -> None:
        """The next samples: times ``t`` (non-decreasing) and values ``(samples, lines)``."""
        t = np.asarray(t, dtype=float)
        if len(t) == 0:
            return
        y = np.asarray(y, dtype=float).reshape(len(t), self.lines)
        if self.count == 0:
            self._t0 = float(t[0])
        self.count += len(t)
        if self.level is None:
            self._raw.append((t, y))
            if self.count <= self.max_points:
                return
            # Too long to keep whole: the finest level of time buckets that fits.
            t = np.concatenate([r[0] for r in self._raw])
            y = np.concatenate([r[1] for r in self._raw])
            self._raw = []
            level = 0
            while len(np.unique(self._ids_of(t, level))) > self.buckets:
                level += 1
            self.level = level
            self._b, self._ids = _reduce(_as_buckets(0, t, y), self._ids_of(t, level))
            return
        ids = self._ids_of(t, self.level)
        new, ids = _reduce(_as_buckets(self.count - len(t), t, y), ids)
        self._b, self._ids = _reduce(_concat(self._b, new), np.concatenate([self._ids, ids]))
        while len(self._ids) > self.buckets:
            self.level += 1
            self._b, self._ids = _reduce(self._b, self._ids >> 1)

    def _ids_of(self, t: np.ndarray, level: int) -> np.ndarray:
        return np.floor((t - self._t0) / (BASE_WIDTH_S * 2.0 ** level)).astype(np.int64)

    def finish(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Every line's (t, y), at most ``max_points`` points each, in time order."""
        if self.level is None:
            t = np.concatenate([np.zeros(0)] + [r[0] for r in self._raw])
            y = np.concatenate([np.zeros((0, self.lines))] + [r[1] for r in self._raw])
            return [(t, y[:, j]) for j in range(self.lines)]
        return [_points(self._b, j) for j in range(self.lines)]


def _as_buckets(start: int, t: np.ndarray, y: np.ndarray) -> dict[str, np.ndarray]:
    """Every sample its own bucket (``start``: the index of the first)."""
    i = start + np.arange(len(t), dtype=np.int64)
    ii = np.repeat(i[:, None], y.shape[1], axis=1)
    tt = np.repeat(t[:, None], y.shape[1], axis=1)
    return {"first_i": i, "first_t": t, "lo_i": ii, "lo_t": tt, "lo_y": y,
            "hi_i": ii, "hi_t": tt, "hi_y": y}


def _concat(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    return {k: np.concatenate([a[k], b[k]]) for k in _FIELDS}


def _reduce(b: dict[str, np.ndarray], ids: np.ndarray) -> tuple[dict[str, np.ndarray],
                                                                 np.ndarray]:
    """Buckets with equal (consecutive, non-decreasing) ids merged into one: the lowest
    and the highest value of each line, the earliest sample of equal ones."""
    if len(ids) == 0:
        return b, ids
    starts = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]])
    if len(starts) == len(ids):
        return b, ids
    out = {"first_i": b["first_i"][starts], "first_t": b["first_t"][starts]}
    for side, pick in (("lo", np.fmin), ("hi", np.fmax)):
        y = b[f"{side}_y"]
        best = pick.reduceat(y, starts, axis=0)                  # NaN only if all are
        lengths = np.diff(np.r_[starts, len(ids)])
        hit = y == np.repeat(best, lengths, axis=0)
        big = np.iinfo(np.int64).max
        row = np.minimum.reduceat(np.where(hit, np.arange(len(ids))[:, None], big),
                                  starts, axis=0)
        row = np.where(row == big, starts[:, None], row)          # all NaN: the first
        cols = np.arange(y.shape[1])[None, :]
        out[f"{side}_i"] = b[f"{side}_i"][row, cols]
        out[f"{side}_t"] = b[f"{side}_t"][row, cols]
        out[f"{side}_y"] = best
    return out, ids[starts]


def _points(b: dict[str, np.ndarray], j: int) -> tuple[np.ndarray, np.ndarray]:
    """Line ``j``: both extremes of every bucket (one NaN point for a bucket of NaN only),
    by sample index, each sample once."""
    empty = np.isnan(b["lo_y"][:, j])
    i = np.concatenate([np.where(empty, b["first_i"], b["lo_i"][:, j]),
                        np.where(empty, b["first_i"], b["hi_i"][:, j])])
    t = np.concatenate([np.where(empty, b["first_t"], b["lo_t"][:, j]),
                        np.where(empty, b["first_t"], b["hi_t"][:, j])])
    y = np.concatenate([b["lo_y"][:, j], b["hi_y"][:, j]])
    _, first = np.unique(i, return_index=True)      # sorted by index, duplicates once
    return t[first], y[first]
