"""What a face needs from a reading of the arm, derived without the executor (pure).

- :class:`VelocityWindow`: joint velocities as the least-squares slope of the measured
  positions over the last window of samples (the same estimate as :mod:`seqrun.arm.tracking`;
  one cycle's difference quotient is useless on a loaded host).
- :func:`joint_flags`: each joint's state flag names and whether any joint is at fault, from
  the driver's decoded states (:mod:`seqrun.drivers.base`): the full state where one was
  read, else the state of the reading. The codes themselves are the driver's business.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping, Sequence
from functools import lru_cache
from typing import TYPE_CHECKING

from seqrun.arm.tracking import MIN_SPAN_FRACTION, VELOCITY_WINDOW_S

if TYPE_CHECKING:
    from seqrun.arm.joint_values import JointState
    from seqrun.drivers.base import CycleState


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


#: What a drive's ``describe()`` says for "no flag" (PowerCube: "OK", "none"): not a flag.
NO_FLAGS = frozenset({"", "ok", "none"})


@lru_cache(maxsize=4096)
def flag_names(text: str) -> tuple[str, ...]:
    """The flag names in a drive's ``describe()`` text (``"HOME_OK|RAMP_END"``)."""
    return tuple(n for n in text.split("|") if n.strip().lower() not in NO_FLAGS)


#: (cycle state type, code) -> (names, refuses motion): the per-cycle states repeat, and
#: describing one costs more than a control cycle can spare for every joint.
_CYCLE_NAMES: dict[tuple[type, int], tuple[tuple[str, ...], bool]] = {}


def _cycle_names(state: CycleState) -> tuple[tuple[str, ...], bool]:
    key = (type(state), int(state))
    found = _CYCLE_NAMES.get(key)
    if found is None:
        if len(_CYCLE_NAMES) > 4096:
            _CYCLE_NAMES.clear()
        found = _CYCLE_NAMES[key] = (flag_names(state.describe()), bool(state.refuses_motion))
    return found


def joint_flags(joint_names: Sequence[str], modules: Sequence[int],
                states: Mapping[int, CycleState],
                full: Mapping[int, JointState] | None = None
                ) -> tuple[dict[str, tuple[str, ...]], bool]:
    """``({joint: flag names}, any fault)`` as the driver decoded them: a joint's full
    state (where one was read) wins over the state of its last reading; from the latter
    alone a fault is a joint that refuses motion (a fault, a Halt, or not homed yet)."""
    flags: dict[str, tuple[str, ...]] = {}
    fault = False
    for name, module in zip(joint_names, modules):
        word = full.get(module) if full else None
        if word is not None:
            names, bad = flag_names(word.text), word.faulted
        else:
            state = states.get(module)
            names, bad = _cycle_names(state) if state is not None else ((), False)
        flags[name] = names
        fault = fault or bad
    return flags, fault
