"""What a run returns: per-step and whole-run results, the operator's abort, exit codes.

Pure data, no I/O: the executor fills them, the run log, the reports and every face read
them (``from seqrun.executor import ...`` keeps working: it re-exports these).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

# Exit codes (shared with the CLI; defined where the CLI can read them without the executor).
from seqrun.defaults import (EXIT_FAULT, EXIT_INVALID, EXIT_OK,  # noqa: F401
                             EXIT_OPERATOR_ABORT, EXIT_USAGE)
from seqrun.errors import (BusError, ModuleFaultError, ModuleTimeoutError, PlanningError,
                           RunAborted, SeqrunError)

__all__ = ["EXIT_FAULT", "EXIT_INVALID", "EXIT_OK", "EXIT_OPERATOR_ABORT", "EXIT_USAGE",
           "OperatorAbort", "RunResult", "StepResult", "UntakenBranch", "fault_cause",
           "halt_fields", "latched_message"]


class OperatorAbort(SeqrunError):
    """The operator asked to stop (controlled stop already done when raised)."""


@dataclass
class StepResult:
    number: int
    kind: str
    label: str
    location: str
    status: str = "pending"              # passed | failed | aborted | skipped
    started: float | None = None
    finished: float | None = None
    planned_duration_s: float | None = None
    detail: dict[str, Any] = field(default_factory=dict)
    #: The requirements the step verifies and its tags, as the sequence file says them.
    verifies: list[str] = field(default_factory=list)
    tags: list[str] = field(default_factory=list)

    @classmethod
    def planned(cls, step: Any, label: str, location: str) -> StepResult:
        """The pending result of a loaded step (its ``verifies``/``tags`` from its params)."""
        params = getattr(step, "params", None)
        return cls(step.number, step.kind, label, location,
                   verifies=list(getattr(params, "verifies", None) or ()),
                   tags=list(getattr(params, "tags", None) or ()))

    @property
    def duration_s(self) -> float | None:
        if self.started is None or self.finished is None:
            return None
        return self.finished - self.started

    def as_dict(self) -> dict:
        return {"number": self.number, "kind": self.kind, "label": self.label,
                "location": self.location, "status": self.status,
                "duration_s": _round(self.duration_s),
                "planned_duration_s": _round(self.planned_duration_s),
                # Only when given: a file without them reports exactly as before.
                **({"verifies": list(self.verifies)} if self.verifies else {}),
                **({"tags": list(self.tags)} if self.tags else {}),
                **self.detail}


@dataclass(frozen=True)
class UntakenBranch:
    """A branch of a step's flow keys that a run did not take (seqrun/execution/flow.py)."""

    step: int
    key: str              # "if", "skip_if", "repeat while", "retry" or "on_fail"
    value: bool | None    # the condition's value never seen (None: retry, on_fail)
    line: str             # as "not verified" lists it

    def same_branch(self, other: UntakenBranch) -> bool:
        """The same branch (of a run with other parameter values, whose texts may differ)."""
        return (self.step, self.key, self.value) == (other.step, other.key, other.value)


@dataclass
class RunResult:
    status: str                          # passed | failed | aborted | invalid
    exit_code: int
    message: str
    steps: list[StepResult]
    started: float
    finished: float
    fault: dict[str, Any] | None = None
    not_verified: list[str] = field(default_factory=list)
    min_heights_mm: dict[str, float] = field(default_factory=dict)
    extra: dict[str, Any] = field(default_factory=dict)
    #: Modules that reported a fault (ERROR, HALTED, ...) when the run started, before
    #: seqrun sent anything but reads: ``[{"module", "joint", "flags"}]``.
    latched_at_start: list[dict[str, Any]] = field(default_factory=list)
    #: The branches of the steps' if/skip_if, repeat and retry this run did not take.
    branches_not_taken: list[UntakenBranch] = field(default_factory=list)

    @property
    def duration_s(self) -> float:
        return self.finished - self.started

    @property
    def planned_duration_s(self) -> float:
        return sum(s.planned_duration_s or 0.0 for s in self.steps)


def _round(x: float | None, nd: int = 4) -> float | None:
    return None if x is None else round(float(x), nd)


def fault_cause(exc: BaseException) -> tuple[str, int | None]:
    """``(cause, module)`` of a fault record for what ended a run or a jog: the cause a
    check named, else the kind of failure (``internal_error`` for a bug)."""
    if isinstance(exc, RunAborted):
        return exc.cause, exc.module
    if isinstance(exc, ModuleTimeoutError):
        return "no_acknowledge", exc.module
    if isinstance(exc, ModuleFaultError):
        return "module_fault", exc.module
    if isinstance(exc, PlanningError):
        return "planning", None
    if isinstance(exc, BusError):
        return "bus_error", getattr(exc, "module", None)
    return "internal_error", None


class _Confirmation(Protocol):
    def as_dict(self) -> dict[str, Any]: ...


def halt_fields(confirmation: _Confirmation | None) -> dict[str, Any]:
    """``halt_sent``, ``halt_confirmed``, ``modules_not_halted`` for a fault record, from
    the emergency Halt's confirmation (None: no Halt was sent)."""
    if confirmation is None:
        return {"halt_sent": False, "halt_confirmed": False}
    return confirmation.as_dict()


def latched_message(latched: list[dict[str, Any]]) -> str:
    """What the operator is told of faults the modules reported before a run sent anything
    but reads (``RunResult.latched_at_start``)."""
    which = "; ".join(f"module {e['module']} ({e['joint']}): {e['flags']}" for e in latched)
    return (f"fault latched before this run (emergency stop pressed, or a previous "
            f"run halted?): {which}")
