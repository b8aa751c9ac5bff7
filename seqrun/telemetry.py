"""What a face needs from a reading of the arm, derived without the executor (pure).

- :class:`VelocityWindow`: joint velocities as the least-squares slope of the measured
  positions over the last window of samples (the same estimate as :mod:`seqrun.tracking`;
  one cycle's difference quotient is useless on a loaded host).
- :func:`joint_flags`: each joint's state flag names, from its state word where one was read,
  else from the short state byte of the extended acknowledge.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping, Sequence

import numpy as np

from seqrun.powercube.protocol import ShortState, StateFlag
from seqrun.tracking import MIN_SPAN_FRACTION, VELOCITY_WINDOW_S


class VelocityWindow:
    """Feed ``(t, joints)`` samples; :meth:`velocity` is the slope over the last window."""

    def __init__(self, window_s: float = VELOCITY_WINDOW_S) -> None:
        self.window_s = window_s
        self._samples: deque[tuple[float, np.ndarray]] = deque()

    def add(self, t: float, joints_deg: Sequence[float]) -> None:
        if self._samples and t <= self._samples[-1][0]:
            if t < self._samples[-1][0]:  # a new time base (a new run): start over
                self._samples.clear()
            else:
                return
        self._samples.append((t, np.asarray(joints_deg, dtype=float)))
        while self._samples and t - self._samples[0][0] > self.window_s + 1e-9:
            self._samples.popleft()

    def clear(self) -> None:
        self._samples.clear()

    def velocity(self) -> list[float] | None:
        """deg/s per joint, or None while the samples span too little of the window."""
        if len(self._samples) < 2:
            return None
        t = np.array([s[0] for s in self._samples])
        if t[-1] - t[0] < MIN_SPAN_FRACTION * self.window_s - 1e-9:
            return None
        q = np.stack([s[1] for s in self._samples])
        dt = t - t.mean()
        slope = (dt[:, None] * (q - q.mean(axis=0))).sum(axis=0) / float((dt * dt).sum())
        return [round(float(v), 3) for v in slope]


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
        word = words.get(str(module), words.get(module))  # type: ignore[call-overload]
        if isinstance(word, StateFlag):
            flags[name] = tuple(word.describe().split("|")) if word else ()
            fault = fault or bool(word & StateFlag.FAULTS)
        elif isinstance(word, str):
            flags[name] = tuple(n for n in word.split("|") if n and n != "none")
            fault = fault or any(n in StateFlag.__members__ and StateFlag[n] & StateFlag.FAULTS
                                 for n in flags[name])
        else:
            s = ShortState(int(state))
            flags[name] = () if not s else tuple(s.describe().split("|"))
            fault = fault or bool(s & ShortState.NOT_OK)
    return flags, fault
