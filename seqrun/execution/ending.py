"""How a run ends: the emergency Halt (sent first, then confirmed by reading every module
back), the fault record, and the run's result.

Every fault, every refused motion and every bug in a step ends the same way: Halt through
the driver (:meth:`~seqrun.executor.Executor.emergency_halt`), the cause named from the
driver's decoded state, exit 3. An operator's abort ends with the arm holding (130); a Halt
asked for while nothing moves is sent and reported like any Halt.
"""

from __future__ import annotations

import traceback
from typing import TYPE_CHECKING, Any

from seqrun.errors import RunAborted
from seqrun.results import (EXIT_FAULT, EXIT_OPERATOR_ABORT, RunResult, StepResult,
                            fault_cause, halt_fields)
from seqrun.stop_requests import FROM_OUTSIDE, OPERATOR_HALT

if TYPE_CHECKING:
    from seqrun.execution.run import Run

#: (status, exit code, message, fault record or None): how a run ends.
Ending = tuple[str, int, str, "dict[str, Any] | None"]


def round4(x: float | None, nd: int = 4) -> float | None:
    """A duration for the event log (None stays None)."""
    return None if x is None else round(float(x), nd)


def emergency_halt(run: Run) -> bool:
    """Halt every module before reading anything, then confirm it by reading every
    module's state back (the driver's ``halt_and_confirm``). Done once per run: a later
    call returns the first result. Returns whether the Halt was sent; the confirmation is
    in ``run.halt_result``."""
    if run.halt_result is not None:
        return run.halt_result.sent
    result = run.halt_result = run.driver.halt_and_confirm()
    names = dict(zip(run.modules, run.arm.joint_names))
    if not result.sent:
        run.emit("halt_failed", error=result.error, message=result.describe(names))
    elif result.confirmed:
        run.emit("halt_confirmed", modules=list(result.modules_confirmed),
                 attempts=result.attempts, duration_s=round4(result.duration_s))
    else:
        run.emit("halt_unconfirmed", modules=list(result.modules_unconfirmed),
                 attempts=result.attempts, duration_s=round4(result.duration_s),
                 states={str(k): v.describe() for k, v in result.states.items()},
                 message=result.describe(names))
    return result.sent


def show_state_after_halt(run: Run) -> None:
    """After a confirmed Halt, the modules' state for the display and the event log (an
    unconfirmed Halt has its own event naming the modules that did not answer)."""
    if run.halt_result is not None and run.halt_result.confirmed:
        run.refresh_measurement("halt")


def halt_note(run: Run) -> str:
    """What the operator must know about the Halt beyond "sent", or ''."""
    result = run.halt_result
    if result is None or result.confirmed:
        return ""
    return "; " + result.describe(dict(zip(run.modules, run.arm.joint_names)))


def _fault(run: Run, cause: str, module: int | None, message: str,
           step: int | None) -> dict[str, Any]:
    return {"cause": cause, "module": module, "message": message, "step": step,
            **halt_fields(run.halt_result)}


def preflight_failed(run: Run, exc: Exception) -> Ending:
    """The preflight raised (a module that does not answer): nothing moved, but Halt."""
    run.emergency_halt()
    cause, module = fault_cause(exc)
    message = run.describe_error(exc) + halt_note(run)
    fault = _fault(run, cause, module, message, None)
    run.emit("fault", **fault)
    show_state_after_halt(run)
    return "failed", EXIT_FAULT, message, fault


def step_aborted(run: Run, step, result: StepResult, exc: BaseException) -> Ending:
    """An operator abort ended the step (controlled stop, or before anything moved); a
    Halt asked for meanwhile is sent and reported like any Halt."""
    status, code, message, fault = "aborted", EXIT_OPERATOR_ABORT, str(exc), None
    halt = run.stops.halt_request
    if halt is not None:
        # A Halt asked for while nothing moved (a question, between steps): it is sent and
        # reported like any Halt.
        halted = run.emergency_halt()
        show_state_after_halt(run)
        message += (f"; {halt.reason}: Halt " + ("sent" if halted else "could not be sent")
                    + halt_note(run))
        if halt.cause != OPERATOR_HALT:
            status, code = "failed", EXIT_FAULT
        fault = _fault(run, halt.cause, None, message, step.number)
        run.emit("fault", **fault)
    result.status = "aborted"
    result.finished = run.elapsed_s()
    result.detail.update(run.tracking_figures())
    run.emit("operator_abort", message=message)
    return status, code, message, fault


def step_failed(run: Run, step, result: StepResult, exc: Exception) -> Ending:
    """Any exception of a step, even a bug: Halt, the cause named, exit 3 (130 for the
    operator's own Halt)."""
    run.emergency_halt()
    exc = run.stops.operator_halt_seen(exc)
    cause, module = fault_cause(exc)
    if cause == "internal_error":
        run.emit("internal_error", traceback=traceback.format_exc())
        exc = RunAborted(cause, f"internal error ({type(exc).__name__}: {exc}); "
                                "the arm was halted; the traceback is in the event log")
    if cause == OPERATOR_HALT:
        status, code = "aborted", EXIT_OPERATOR_ABORT
    else:
        status, code = "failed", EXIT_FAULT
    message = run.describe_error(exc) + halt_note(run)
    halt = run.stops.halt_request
    if halt is not None and halt.cause in FROM_OUTSIDE and cause != halt.cause:
        # What the modules showed (HALTED) came from outside: name the source.
        cause, message = halt.cause, f"{halt.reason}: {message}"
    fault = _fault(run, cause, module, message, step.number)
    result.status = "failed" if code == EXIT_FAULT else "aborted"
    result.finished = run.elapsed_s()
    result.detail.update(jsonable(getattr(exc, "detail", None) or {}))
    result.detail.update(run.tracking_figures())   # up to the fault
    result.detail.setdefault("error", message)
    run.emit("fault", **fault)
    show_state_after_halt(run)
    return status, code, message, fault


def step_interrupted(run: Run, step, result: StepResult, results: list[StepResult],
                     exc: BaseException) -> None:
    """Anything else leaving a step (KeyboardInterrupt, SystemExit) still halts the arm
    before it propagates; the run folder is finished with this result first
    (``run.interrupted_result``)."""
    run.emergency_halt()
    fault = _fault(run, "interrupted", None, repr(exc), step.number)
    run.emit("fault", **fault)
    result.status = "failed"
    result.finished = run.elapsed_s()
    run.current_step = None
    run.driver.stop_watchdog_keeper()
    run.interrupted_result = finish(run, results, "failed", EXIT_FAULT,
                                    f"interrupted ({exc!r}); the arm was halted", fault)


def halt_after_last_step(run: Run) -> Ending:
    """A Halt asked for after the last step: nothing moves, but it is sent as asked."""
    halt = run.stops.halt_request
    assert halt is not None
    run.emergency_halt()
    status, code = (("aborted", EXIT_OPERATOR_ABORT) if halt.cause == OPERATOR_HALT
                    else ("failed", EXIT_FAULT))
    message = f"{halt.reason} after the last step; Halt sent" + halt_note(run)
    fault = _fault(run, halt.cause, None, message, None)
    run.emit("fault", **fault)
    return status, code, message, fault


def finish(run: Run, results: list[StepResult], status: str, code: int, message: str,
           fault: dict | None, **extra: Any) -> RunResult:
    """The run's result, announced (``run_finished``)."""
    checks = run.checks
    result = RunResult(status, code, message, results, 0.0, run.elapsed_s(), fault,
                       list(dict.fromkeys(run.not_verified)),
                       {k: round(v, 1) for k, v in checks.min_heights_mm.items()})
    result.extra = extra
    result.latched_at_start = list(run.latched.at_start)
    run.emit("run_finished", status=status, exit_code=code, message=message,
             duration_s=round4(result.duration_s),
             planned_duration_s=round4(result.planned_duration_s), **extra)
    return result


def jsonable(d: dict) -> dict:
    """A step's details with numpy values as plain ones (the event log is JSON)."""
    import numpy as np

    from seqrun.execution.run import rounded

    out = {}
    for k, v in d.items():
        if isinstance(v, np.ndarray):
            v = rounded(v)
        elif isinstance(v, (np.floating,)):
            v = float(v)
        out[k] = v
    return out
