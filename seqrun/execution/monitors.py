"""Monitors: a step's and the sequence's invariants, evaluated on every reading the run
loop takes.

A step's ``monitors:`` (:class:`~seqrun.steps.params.MonitorSpec`) are armed when the step
starts and disarmed when it ends; the sequence's (its top-level ``monitors:``) are armed
with every step, their counts kept from step to step. Every reading of the arm during a
step (a move's cycles, a wait's, a checkpoint's) is held against each of them; one that has
failed for ``persist_cycles`` readings in a row trips: ``halt`` raises a fault from inside
the cycle (the run's fault path sends the Halt and ends with exit 3), ``stop`` raises the
same fault marked ``controlled`` (the motion under way is brought to a jerk-limited stop
first, seqrun/execution/streaming.py), ``warn`` emits an event once per episode and the run
goes on. Expressions are parsed once, at arming.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from seqrun.errors import RunAborted
from seqrun.steps._telemetry import reading_values, values_read
from seqrun.steps.expressions import Expression, ExpressionError, parse

__all__ = ["MonitorTripped", "Monitors"]


class MonitorTripped(RunAborted):
    """A monitor with ``action: halt`` or ``stop`` tripped; ``controlled``: stop (the motion
    under way comes to a controlled stop before the fault's Halt)."""

    controlled: bool = False


@dataclass
class _Armed:
    spec: Any                   # MonitorSpec
    expression: Expression
    failing: int = 0            # readings in a row the invariant has not held
    warned: bool = False        # this episode's warning is out
    scope: str = "step"         # "sequence": the sequence's, armed with every step


@dataclass
class Monitors:
    """The monitors of the running step."""

    arm: Any                                    # ArmDescription
    emit: Callable[..., None]
    _armed: list[_Armed] = field(default_factory=list)
    _names: frozenset[str] = frozenset()
    _last: Any = None
    _step_t0: float = 0.0
    _params: Mapping[str, Any] = field(default_factory=dict)
    #: The sequence's monitors (armed with every step by :meth:`start_step`).
    _sequence: list[_Armed] = field(default_factory=list)

    def start_sequence(self, monitors: Sequence[Any], *,
                       param_types: Mapping[str, tuple[str, str | None]] | None = None
                       ) -> None:
        """The sequence's ``monitors``, watched during every step from now on."""
        joints = len(self.arm.joints)
        self._sequence = [_Armed(m, parse(m.while_, joints=joints, params=param_types),
                                 scope="sequence") for m in monitors]

    def start_step(self, monitors: Sequence[Any], t: float, *,
                   param_types: Mapping[str, tuple[str, str | None]] | None = None,
                   param_values: Mapping[str, Any] | None = None) -> None:
        """Arm ``monitors`` (a step's); ``param_types``/``param_values``: the sequence's
        parameters their expressions may read as ``params.NAME``."""
        joints = len(self.arm.joints)
        self._armed = self._sequence + [
            _Armed(m, parse(m.while_, joints=joints, params=param_types)) for m in monitors]
        self._params = {f"params.{k}": v for k, v in (param_values or {}).items()}
        self._names = frozenset().union(*(a.expression.names for a in self._armed))
        self._last = None
        self._step_t0 = t

    def stop(self) -> None:
        self._armed = []
        self._last = None

    @property
    def active(self) -> bool:
        return bool(self._armed)

    def observe(self, reading: Any, commanded: Any, sequence_time_s: float) -> None:
        """Hold ``reading`` against every armed monitor. :raises MonitorTripped:"""
        if not self._armed:
            return
        values = reading_values(self.arm, reading, self._last, commanded, self._names,
                                step_time_s=reading.t - self._step_t0,
                                sequence_time_s=sequence_time_s)
        values.update(self._params)
        self._last = reading
        for armed in self._armed:
            try:
                holds = bool(armed.expression.evaluate(values))
            except ExpressionError:
                # a value not there yet (a velocity at the first reading, no target yet):
                # nothing to hold the invariant against in this cycle
                continue
            if holds:
                armed.failing, armed.warned = 0, False
                continue
            armed.failing += 1
            if armed.warned or armed.failing < armed.spec.persist_cycles:
                continue  # (a warning is given once until the invariant holds again)
            self._trip(armed, values)

    def _trip(self, armed: _Armed, values: dict[str, Any]) -> None:
        spec, expression = armed.spec, armed.expression
        read = values_read(values, expression)
        what = f"monitor '{spec.while_}'" + (f" ({spec.message})" if spec.message else "")
        shown = ", ".join(f"{k} = {v}" for k, v in read.items())
        if armed.scope == "sequence":
            what = "sequence " + what
        self.emit("monitor_tripped", condition=spec.while_, action=spec.action,
                  cycles=armed.failing, values=read,
                  **({"message": spec.message} if spec.message else {}),
                  **({"scope": "sequence"} if armed.scope == "sequence" else {}))
        if spec.action in ("halt", "stop"):
            self.stop()
            tripped = MonitorTripped("monitor", f"{what} did not hold: {shown}",
                                     detail={"monitor": spec.while_, "values": read,
                                             "action": spec.action})
            tripped.controlled = spec.action == "stop"
            raise tripped
        armed.warned = True
