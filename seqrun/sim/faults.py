"""Faults the simulated arm can be told to suffer, and the ``MODULE:KIND@SECONDS`` spec syntax.

A :class:`Fault` happens ``at`` seconds after the simulated arm was created, to one module
or to all of them (``module=None``). The kinds, and what the module does from then on:

==============  ===========================================================================
``tow_error``   following error: stops at once, state ERROR|TOW_ERROR|HALTED; Reset clears it
``halt``        the red emergency push-button: stops at once, HALTED; Reset clears it
``no_ack``      its transmitter is dead: it still executes every request (addressed or
                broadcast) and keeps moving, but no acknowledge ever reaches the bus
``drop_acks``   each acknowledge is lost with probability ``rate`` (seeded, deterministic)
``stuck``       the joint no longer follows: commands are accepted and acknowledged
                normally, no error flag, but the position stays where it is
``missing``     the module is gone (unplugged, no power): never answers, ignores
                broadcasts, does not move
==============  ===========================================================================

Spec syntax (the ``--fault`` option of ``seqrun sim serve`` and the ``faults=`` argument of
the ``seqrun-sim`` bus)::

    4:tow_error@2.5          module 4, tow error 2.5 s after start
    all:halt@1               every module, emergency stop after 1 s
    3:drop_acks=0.3@0        module 3 loses 30 % of its acknowledges from the start
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable
from dataclasses import dataclass

#: Every kind of fault, in the order of the table above.
FAULT_KINDS = ("tow_error", "halt", "no_ack", "drop_acks", "stuck", "missing")

_SPEC = re.compile(r"^(?P<module>[^:@=]+):(?P<kind>[^:@=]+)(?:=(?P<rate>[^@]*))?@(?P<at>.*)$")


@dataclass(frozen=True)
class Fault:
    """One scheduled fault. ``module=None`` means every module of the arm."""

    module: int | None
    kind: str
    at: float
    rate: float | None = None

    def __post_init__(self) -> None:
        if self.module is not None and (isinstance(self.module, bool)
                                        or not isinstance(self.module, int)
                                        or not 1 <= self.module <= 31):
            raise ValueError(f"fault module must be 1..31 or None (all), got {self.module!r}")
        if self.kind not in FAULT_KINDS:
            raise ValueError(f"unknown fault kind {self.kind!r} (one of {', '.join(FAULT_KINDS)})")
        if not isinstance(self.at, (int, float)) or not math.isfinite(self.at) or self.at < 0:
            raise ValueError(f"fault time must be a finite number of seconds >= 0, got {self.at!r}")
        if self.kind == "drop_acks":
            if self.rate is None or not 0 < self.rate <= 1:
                raise ValueError(f"drop_acks needs a rate in (0, 1], got {self.rate!r}")
        elif self.rate is not None:
            raise ValueError(f"fault kind {self.kind!r} takes no rate")

    @property
    def spec(self) -> str:
        """The spec string this fault parses from."""
        module = "all" if self.module is None else str(self.module)
        rate = "" if self.rate is None else f"={self.rate:g}"
        return f"{module}:{self.kind}{rate}@{self.at:g}"

    def __str__(self) -> str:
        return self.spec


def parse_fault_spec(spec: str) -> Fault:
    """Parse ``MODULE:KIND[=RATE]@SECONDS``; MODULE is 1..31 or ``all``.

    :raises ValueError: with a one-line message that names the spec and the problem.
    """
    text = spec.strip()
    match = _SPEC.match(text)
    if match is None:
        if "@" not in text:
            raise ValueError(f"fault spec {spec!r}: missing '@SECONDS' (e.g. 4:tow_error@2.5)")
        raise ValueError(f"fault spec {spec!r}: expected MODULE:KIND[=RATE]@SECONDS "
                         f"(e.g. 4:tow_error@2.5, all:halt@1, 3:drop_acks=0.3@0)")
    module_text = match["module"].strip()
    if module_text.lower() == "all":
        module = None
    else:
        try:
            module = int(module_text)
        except ValueError:
            raise ValueError(f"fault spec {spec!r}: module must be 1..31 or 'all', "
                             f"got {module_text!r}") from None
        if not 1 <= module <= 31:
            raise ValueError(f"fault spec {spec!r}: module must be 1..31 or 'all', got {module}")
    kind = match["kind"].strip()
    if kind not in FAULT_KINDS:
        raise ValueError(f"fault spec {spec!r}: unknown kind {kind!r} "
                         f"(one of {', '.join(FAULT_KINDS)})")
    try:
        at = float(match["at"])
    except ValueError:
        raise ValueError(f"fault spec {spec!r}: time must be seconds, "
                         f"got {match['at']!r}") from None
    if not math.isfinite(at) or at < 0:
        raise ValueError(f"fault spec {spec!r}: time must be >= 0 seconds, got {match['at']}")
    rate_text = match["rate"]
    rate = None
    if kind == "drop_acks":
        if rate_text is None:
            raise ValueError(f"fault spec {spec!r}: drop_acks needs a rate, e.g. "
                             f"{module_text}:drop_acks=0.3@{match['at']}")
        try:
            rate = float(rate_text)
        except ValueError:
            raise ValueError(f"fault spec {spec!r}: rate must be a number in (0, 1], "
                             f"got {rate_text!r}") from None
        if not 0 < rate <= 1:
            raise ValueError(f"fault spec {spec!r}: rate must be in (0, 1], got {rate_text}")
    elif rate_text is not None:
        raise ValueError(f"fault spec {spec!r}: kind {kind!r} takes no rate")
    return Fault(module, kind, at, rate)


def parse_faults(specs: str | Fault | Iterable[str | Fault] | None) -> list[Fault]:
    """Faults from a mix of :class:`Fault` objects and spec strings.

    A single string may hold several specs separated by commas or whitespace (the form a
    python-can config file or ``--bus-kwargs`` can carry).
    """
    if specs is None:
        return []
    if isinstance(specs, (str, Fault)):
        specs = [specs]
    faults = []
    for item in specs:
        if isinstance(item, Fault):
            faults.append(item)
        elif isinstance(item, str):
            faults.extend(parse_fault_spec(part) for part in re.split(r"[,\s]+", item) if part)
        else:
            raise TypeError(f"a fault must be a Fault or a spec string, got {item!r}")
    return faults
