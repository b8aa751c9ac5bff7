"""What a face needs from a reading of the arm, derived without the executor (pure).

- :class:`VelocityWindow`: joint velocities as the least-squares slope of the measured
  positions over the last window of samples (the same estimate as :mod:`seqrun.tracking`;
  one cycle's difference quotient is useless on a loaded host).
- :func:`joint_flags`: each joint's state flag names, from its state word where one was read,
  else from the short state byte of the extended acknowledge.
"""

from __future__ import annotations

from collections import deque
from functools import lru_cache
from collections.abc import Mapping, Sequence

from seqrun.powercube.protocol import ShortState, StateFlag
from seqrun.tracking import MIN_SPAN_FRACTION, VELOCITY_WINDOW_S


class VelocityWindow:
    """Feed ``(t, joints)`` samples; :meth:`velocity` is the slope over the last window.

    Plain Python over a dozen samples: cheaper than building arrays every control cycle."""

    def __init__(self, window_s: float = VELOCITY_WINDOW_S) -> None:
        self.window_s = window_s
        self._samples: deque[tuple[float, tuple[float, ...]]] = deque()

    def add(self, t: float, joints_deg: Sequence[float]) -> None:
        t = float(t)
        if self._samples and t <= self._samples[-1][0]:
            if t < self._samples[-1][0]:  # a new time base (a new run): start over
                self._samples.clear()
            else:
                return
        self._samples.append((t, tuple(float(x) for x in joints_deg)))
        while self._samples and t - self._samples[0][0] > self.window_s + 1e-9:
            self._samples.popleft()

    def clear(self) -> None:
        self._samples.clear()

    def velocity(self) -> list[float] | None:
        """deg/s per joint, or None while the samples span too little of the window."""
        samples = self._samples
        if len(samples) < 2:
            return None
        t0, t1 = samples[0][0], samples[-1][0]
        if t1 - t0 < MIN_SPAN_FRACTION * self.window_s - 1e-9:
            return None
        n = len(samples)
        t_mean = sum(s[0] for s in samples) / n
        dts = [s[0] - t_mean for s in samples]
        denominator = sum(d * d for d in dts)
        out = []
        for j in range(len(samples[-1][1])):
            q_mean = sum(s[1][j] for s in samples) / n
            slope = sum(d * (s[1][j] - q_mean) for d, s in zip(dts, samples)) / denominator
            out.append(round(slope, 3))
        return out


@lru_cache(maxsize=4096)
def _short_names(state: int) -> tuple[tuple[str, ...], bool]:
    s = ShortState(state)
    return (() if not s else tuple(s.describe().split("|"))), bool(s & ShortState.NOT_OK)


@lru_cache(maxsize=4096)
def _word_names(word: int) -> tuple[tuple[str, ...], bool]:
    w = StateFlag(word)
    return (tuple(w.describe().split("|")) if w else ()), bool(w & StateFlag.FAULTS)


@lru_cache(maxsize=4096)
def _described_names(text: str) -> tuple[tuple[str, ...], bool]:
    names = tuple(n for n in text.split("|") if n and n != "none")
    return names, any(n in StateFlag.__members__ and StateFlag[n] & StateFlag.FAULTS
                      for n in names)


def joint_flags(joint_names: Sequence[str], modules: Sequence[int], short: Sequence[int],
                words: Mapping[str, str] | Mapping[int, StateFlag] | None = None
                ) -> tuple[dict[str, tuple[str, ...]], bool]:
    """``({joint: flag names}, any fault)``. A state word (by module id, as a StateFlag or
    its description) wins over the short state; from the short state alone a fault is
    NOT_OK (a fault, a Halt, or not homed yet)."""
    flags: dict[str, tuple[str, ...]] = {}
    fault = False
    words = words or {}
    for name, module, state in zip(joint_names, modules, short):
        word = words.get(str(module), words.get(module)) if words else None  # type: ignore[call-overload]
        if isinstance(word, StateFlag):
            names, bad = _word_names(int(word))
        elif isinstance(word, str):
            names, bad = _described_names(word)
        else:
            names, bad = _short_names(int(state))
        flags[name] = names
        fault = fault or bad
    return flags, fault
