"""Exceptions of seqrun.

::

    SeqrunError
     ├── UserInputError            bad command-line input or file outside a sequence (exit 2)
     ├── SequenceInvalid           a sequence/arm/pose file failed validation (exit 1);
     │                             carries every SourceError at once
     ├── BusError                  anything between us and the modules
     │    ├── CodecError (ValueError)         a frame that is not valid PowerCube
     │    ├── ModuleTimeoutError (TimeoutError)  no matching acknowledge in time
     │    └── ModuleFaultError                a module reports ERROR/HALTED/TOW_ERROR/...
     ├── PlanningError             ruckig refused the input
     ├── RunAborted                the executor stopped a run (fault, timeout, checkpoint)
     └── Refused                   the arm session refused a command (bad input, wrong
                                   state, the bus held by
                                   another controller); nothing was sent (exit 2)

Messages are written for a test engineer at the arm: they name the module and its
decoded state flags, the file and line, never a Python object.
"""

from __future__ import annotations

from dataclasses import dataclass


class SeqrunError(Exception):
    """Root of all seqrun errors."""


class UserInputError(SeqrunError):
    """Bad command-line input (unknown pose, bad fault spec, missing file)."""


#: What str.splitlines() breaks at, shown as escapes in an error line.
_LINE_BREAKS = {c: repr(chr(c))[1:-1] for c in (0x0A, 0x0B, 0x0C, 0x0D, 0x1C, 0x1D, 0x1E,
                                                  0x85, 0x2028, 0x2029)}


@dataclass(frozen=True)
class SourceError:
    """One problem in a source file, at 1-based ``line`` and ``column``."""

    file: str
    line: int
    column: int
    message: str

    def __str__(self) -> str:  # one line, whatever the file name or a quoted value holds
        return f"{self.file}:{self.line}:{self.column}: {self.message}".translate(_LINE_BREAKS)

    def as_dict(self) -> dict:
        return {"file": self.file, "line": self.line, "column": self.column,
                "message": self.message}


class SequenceInvalid(SeqrunError):
    """A file failed validation; ``errors`` lists every problem found."""

    def __init__(self, errors: list[SourceError]) -> None:
        self.errors = list(errors)
        super().__init__("\n".join(str(e) for e in self.errors))


class BusError(SeqrunError):
    """Communication with the modules failed."""


class CodecError(BusError, ValueError):
    """A frame that cannot be encoded or decoded (wrong length, unknown command, ...)."""


class ModuleTimeoutError(BusError, TimeoutError):
    """A module did not acknowledge a request in time."""

    def __init__(self, module: int, what: str, timeout: float, request: object = None) -> None:
        self.module = module
        self.what = what
        self.timeout = timeout
        #: The request that went unanswered (for a message in the operator's units).
        self.request = request
        super().__init__(f"module {module}: no acknowledge to {what} within {timeout * 1000:.0f} ms")


class ModuleFaultError(BusError):
    """A module reports a fault; ``flags`` is its decoded state (a StateFlag)."""

    def __init__(self, module: int, flags: object, detail: str = "") -> None:
        self.module = module
        self.flags = flags
        name = getattr(flags, "describe", None)
        text = name() if callable(name) else str(flags)
        self.detail = detail
        super().__init__(f"module {module}: {text}" + (f" ({detail})" if detail else ""))


class PlanningError(SeqrunError):
    """The trajectory planner could not plan a move."""


class RunAborted(SeqrunError):
    """The executor aborted a run; ``module`` names the culprit where there is one."""

    def __init__(self, cause: str, message: str, module: int | None = None,
                 detail: dict | None = None, *, retryable: bool = False) -> None:
        self.cause = cause
        self.module = module
        #: A measurement that did not meet its bound while nothing moved (a check, a
        #: wait_until's timeout, a checkpoint, a gripper check): a step's ``retry`` may
        #: run it again. Everything else (faults, Halts, guards, monitors) never is.
        self.retryable = retryable
        #: Measured values for the step's report entry (e.g. a checkpoint's errors).
        self.detail = detail or {}
        super().__init__(message)


class Refused(SeqrunError):
    """The arm session refused a command: bad input (unknown joint or pose, a target
    outside the limits, NaN) or the wrong state (a move while halted, a second activity
    while one runs, the bus held by another controller). One line for the operator; nothing was sent to the arm."""
