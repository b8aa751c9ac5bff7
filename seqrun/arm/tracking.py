"""How well a move followed its plan: following error, final error, peak velocity (pure).

The executor feeds one sample per control cycle (the values it also writes to the event
log, so the figures in report.json can be recomputed from events.jsonl) and reads the
figures when the move ends; the report recomputes the same series from the log.

Velocity is a *windowed* estimate: the least-squares slope of the measured positions over
the last ``window_s`` seconds of samples. One cycle's difference quotient is useless on a
real host: a sample whose timestamp was taken late (the loop stalled after the answers
arrived) and the punctual sample after it are a few milliseconds apart in time but a whole
cycle apart in position, which turns a 15 °/s move into "50 °/s". Over a window of several
cycles a few milliseconds of timestamp error change the slope by a few percent at most.

And the times are the readings' own: when the joints answered, from the bus's time stamps
(``read_t`` of a setpoint), not when the loop got round to them. A stall of the loop while
the answers waited in the interface (60 ms, 250 ms) is no error of a few milliseconds, and
it can split a cycle's pipelined exchange, so that the joints of one reading answered at
different times: each joint's samples then have times of their own (``t_joint``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: Window of the velocity estimate at 100 Hz: 11 samples, jitter averaged out, lag 50 ms.
VELOCITY_WINDOW_S = 0.1
#: Estimates need samples spanning at least this fraction of the window.
MIN_SPAN_FRACTION = 0.5
#: Samples this close to the window's edge still count (float times of a virtual clock).
_EDGE_S = 1e-9


def velocity_window(cycle_s: float) -> float:
    """The estimate's window for a control loop of period ``cycle_s``: at least two and a
    half cycles (a 10 Hz dry run has one sample per 100 ms; the half keeps a window of
    exactly two periods from losing a sample to microseconds of timing)."""
    return max(VELOCITY_WINDOW_S, 2.5 * cycle_s)


def windowed_velocity(t: np.ndarray, q: np.ndarray, window_s: float,
                      t_joint: np.ndarray | None = None) -> np.ndarray:
    """Least-squares slope of ``q`` (samples × joints, or samples) over the samples in
    ``[t[k] - window_s, t[k]]`` for every sample ``k``; NaN where those samples span less
    than ``MIN_SPAN_FRACTION`` of the window (the first samples of a series).
    ``t_joint`` (samples × joints): each joint's own sample times for the slope (the
    window is chosen by ``t``)."""
    t = np.asarray(t, dtype=float)
    q = np.asarray(q, dtype=float)
    flat = q.ndim == 1
    if flat:
        q = q[:, None]
    if t_joint is not None:
        t_joint = np.asarray(t_joint, dtype=float).reshape(q.shape)
        if np.array_equal(t_joint, np.broadcast_to(t[:, None], q.shape)):
            t_joint = None  # one time per sample after all
    n = len(t)
    v = np.full(q.shape, np.nan)
    if n < 2:
        return v[:, 0] if flat else v
    first = np.searchsorted(t, t - window_s - _EDGE_S, side="left")
    ok = (t - t[first]) >= MIN_SPAN_FRACTION * window_s - _EDGE_S
    width = int(np.max(np.arange(n) - first)) + 1
    # Gather each sample's window as a row (padded with the window's first sample,
    # masked out): samples × width, vectorised over the whole series.
    offsets = np.arange(width)[None, :]
    index = first[:, None] + offsets
    valid = index <= np.arange(n)[:, None]
    index = np.where(valid, index, first[:, None])
    tw = t[index]
    count = valid.sum(axis=1)
    t_mean = np.where(valid, tw, 0.0).sum(axis=1) / count
    dt = np.where(valid, tw - t_mean[:, None], 0.0)
    sxx = (dt * dt).sum(axis=1)
    usable = ok & (sxx > 0)
    for j in range(q.shape[1]):
        if t_joint is not None:  # this joint's own times
            tj = t_joint[index, j]
            tj_mean = np.where(valid, tj, 0.0).sum(axis=1) / count
            dt = np.where(valid, tj - tj_mean[:, None], 0.0)
            sxx = (dt * dt).sum(axis=1)
            usable = ok & (sxx > 0)
        qw = q[index, j]
        q_mean = np.where(valid, qw, 0.0).sum(axis=1) / count
        sxy = (dt * np.where(valid, qw - q_mean[:, None], 0.0)).sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            v[:, j] = np.where(usable, sxy / np.where(sxx > 0, sxx, 1.0), np.nan)
    return v[:, 0] if flat else v


class VelocityStream:
    """:func:`windowed_velocity` of a series that arrives a chunk at a time, in bounded
    memory: each chunk is estimated together with the samples of the one window before
    it, so the estimates are those of the whole series (times in non-decreasing order)."""

    def __init__(self, window_s: float) -> None:
        self.window_s = float(window_s)
        self._t = np.zeros(0)
        self._q: np.ndarray | None = None
        self._tj: np.ndarray | None = None

    def feed(self, t: np.ndarray, q: np.ndarray,
             t_joint: np.ndarray | None = None) -> np.ndarray:
        """The estimates of the samples ``t``, ``q`` (samples × joints), the next chunk;
        ``t_joint``: each joint's own sample times (as :func:`windowed_velocity`)."""
        t = np.asarray(t, dtype=float)
        q = np.asarray(q, dtype=float)
        tj = (np.broadcast_to(t[:, None], q.shape) if t_joint is None
              else np.asarray(t_joint, dtype=float).reshape(q.shape))
        if self._q is None or self._tj is None or len(self._t) == 0:
            tt, qq, ttj = t, q, tj
        else:
            tt, qq = np.concatenate([self._t, t]), np.concatenate([self._q, q])
            ttj = np.concatenate([self._tj, tj])
        v = windowed_velocity(tt, qq, self.window_s, ttj)[len(tt) - len(t):]
        if len(tt):
            # The next chunk's windows reach back at most one window (and the edge) from
            # its first sample, which is no earlier than this chunk's last.
            keep = np.searchsorted(tt, tt[-1] - self.window_s - 2 * _EDGE_S, side="left")
            self._t, self._q, self._tj = tt[keep:], qq[keep:], ttj[keep:]
        return v


def sample_time(read_t: float | list[float]) -> float:
    """One time for a sample whose joints answered at ``read_t`` (one time, or one per
    joint): what chooses the samples of a velocity window (rounded as logged)."""
    if isinstance(read_t, (int, float)):
        return float(read_t)
    return round(float(np.mean(read_t)), 6)


def peak_abs(v: np.ndarray) -> np.ndarray:
    """Largest |v| per joint, ignoring NaN (0 where there is no estimate at all)."""
    v = np.abs(np.asarray(v, dtype=float))
    if v.size == 0:
        return np.zeros(v.shape[1:] if v.ndim > 1 else ())
    return np.nan_to_num(np.max(np.where(np.isnan(v), -np.inf, v), axis=0), neginf=0.0)


@dataclass
class MoveTracking:
    """The samples of one move (every streamed cycle, controlled stop included)."""

    window_s: float
    t: list[float] = field(default_factory=list)
    planned: list[np.ndarray] = field(default_factory=list)
    measured: list[np.ndarray] = field(default_factory=list)
    #: Per sample: the joints' own times where they differ (else None: ``t`` for all).
    t_joint: list[np.ndarray | None] = field(default_factory=list)

    def add(self, t: float | list[float], planned_deg, measured_deg) -> None:
        """A sample at ``t``: the reading's time, or one per joint (``read_t``)."""
        if isinstance(t, (int, float)):
            self.t.append(float(t))
            self.t_joint.append(None)
        else:
            self.t.append(sample_time(t))
            self.t_joint.append(np.asarray(t, dtype=float))
        self.planned.append(np.asarray(planned_deg, dtype=float))
        self.measured.append(np.asarray(measured_deg, dtype=float))

    def figures(self, target_deg) -> dict[str, list[float]]:
        """Per joint: largest |planned − measured|, final |target − measured| (at the last
        sample) and the peak of the windowed measured velocity, rounded for the report."""
        if not self.t:
            return {}
        planned = np.array(self.planned)
        measured = np.array(self.measured)
        t = np.array(self.t)
        t_joint = None
        if any(x is not None for x in self.t_joint):
            t_joint = np.array([np.full(measured.shape[1], s) if x is None else x
                                for s, x in zip(t, self.t_joint)])
        velocity = windowed_velocity(t, measured, self.window_s, t_joint)
        return {
            "max_following_error_deg": _r(np.max(np.abs(planned - measured), axis=0)),
            "final_error_deg": _r(np.abs(np.asarray(target_deg, dtype=float) - measured[-1])),
            "peak_measured_velocity_deg_s": _r(peak_abs(velocity)),
        }


def _r(a: np.ndarray, nd: int = 3) -> list[float]:
    return [round(float(x), nd) for x in a]
