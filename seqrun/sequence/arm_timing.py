"""When a step of a campaign's arm can happen, for every timing the run can take (pure).

On the planned time line (:mod:`seqrun.sequence.arm_schedule`) a ``confirm`` lasts 0 s,
a ``reset`` or ``home`` too; in a run they last as long as the operator or the modules
take. Each such step adds an unknown delay ``d >= 0`` (at most ``bound`` s where one is
known). A moment of an arm's track is then a :class:`Stamp`: the latest of a few terms
``c + sum of some delays`` (a ``wait_for`` ends at the later of its arrival and the
signal; a step adds to every term). Between two stamps the offset lies in
[:func:`offset_range`], proved for every value of the delays; when both ends of that
range meet, the two moments keep their planned offset in every run.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

__all__ = ["Stamp", "offset_range", "rigid", "uncertain_delays"]

#: Offsets closer than this (s) count as the same.
SAME_S = 1e-6


@dataclass(frozen=True)
class Stamp:
    """The latest of ``terms``: each ``(delays, seconds)`` is ``seconds`` plus the sum of
    the unknown delays (ids) in ``delays``."""

    terms: tuple[tuple[frozenset[int], float], ...]

    @classmethod
    def zero(cls) -> Stamp:
        return cls(((frozenset(), 0.0),))

    @property
    def planned(self) -> float:
        """The time with every delay 0 (the planned time line)."""
        return max(c for _, c in self.terms)

    def plus(self, seconds: float) -> Stamp:
        return Stamp(tuple((s, c + seconds) for s, c in self.terms))

    def delayed(self, delay: int) -> Stamp:
        return Stamp(tuple((s | {delay}, c) for s, c in self.terms))

    def later(self, other: Stamp) -> Stamp:
        """The later of two moments (a ``wait_for`` meeting its signal)."""
        # a term no larger and waiting for no more delays than another never decides
        kept: list[tuple[frozenset[int], float]] = []
        for term in sorted(self.terms + other.terms, key=lambda t: (-len(t[0]), -t[1])):
            if not any(term[0] <= u[0] and term[1] <= u[1] + SAME_S for u in kept):
                kept.append(term)
        return Stamp(tuple(kept))


def _upper(x: Stamp, y: Stamp, bounds: Mapping[int, float]) -> float:
    """An upper bound of ``x - y`` over every delay value: for every term f of x, some
    term g of y gives x - y <= max over the delays of (f - g)."""
    worst = -math.inf
    for sx, cx in x.terms:
        best = math.inf
        for sy, cy in y.terms:
            extra = sum(bounds.get(d, math.inf) for d in sx - sy)
            best = min(best, cx - cy + extra)
        worst = max(worst, best)
    return worst


def offset_range(x: Stamp, y: Stamp, bounds: Mapping[int, float] | None = None
                 ) -> tuple[float, float]:
    """``[lo, hi]`` holding ``x - y`` for every value of the delays (``bounds``: a delay's
    largest value where known, else unbounded); ``hi`` may be infinite."""
    bounds = bounds or {}
    return -_upper(y, x, bounds), _upper(x, y, bounds)


def rigid(pairs: Iterable[tuple[Stamp, Stamp]], bounds: Mapping[int, float] | None = None
          ) -> bool:
    """Whether every pair keeps its planned offset in every run."""
    for x, y in pairs:
        lo, hi = offset_range(x, y, bounds)
        if hi - lo > SAME_S:
            return False
    return True


def uncertain_delays(*stamps: Stamp) -> set[int]:
    """The delays that some of these moments wait for and others not: those that make
    their offsets unknown."""
    sets = [s for stamp in stamps for s, _ in stamp.terms]
    if not sets:
        return set()
    every = frozenset.intersection(*sets)
    return set(frozenset.union(*sets) - every)
