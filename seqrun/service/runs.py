"""Sequence runs in a session: ``seqrun run``'s (on the caller's thread, the terminal's own
prompts and signals) and the console's (in a worker, questions as events), each with its
run folder, and pause/resume of the run under way.

Both go through :func:`seqrun.service.runner.run_sequence` with the session's driver and
event hub, so a run in the console is exactly a run from the terminal. Part of the arm
session (:mod:`seqrun.service.session`).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from seqrun.errors import Refused
from seqrun.service.activities import (EXIT_FAULT_CODE, Activity, ActivityResult,
                                       activity_result)
from seqrun.service.motion import finite
from seqrun.service.status import RunInfo


#: How long a Resume waits for the run's check of the rest of the sequence (real seconds;
#: the check plans every remaining move: a long sequence takes a few seconds on a slow PC).
RESUME_ANSWER_S = 30.0


class Runs:
    """The sequence runs of one session (its ``arm``, ``project``, ``connection``,
    ``driver``, ``events``, ``zero``, ``log_root``, ``activities``, ``telemetry``,
    ``questions``)."""

    def __init__(self, session: Any) -> None:
        self._session = session

    def run_sequence(self, file: str | Path, *, speed: float = 1.0, step_mode: bool = False,
                     first_step: int = 1, command_mode: str | None = None,
                     log_dir: Path | None = None, html_report: bool = True,
                     loaded=None, assume_yes: bool = False, by: str | None = None) -> Activity:
        """Validate ``file`` (refused with its first error line when invalid), then run it in
        a worker thread with a run folder like ``seqrun run``. Questions (confirm steps,
        ``step_mode``'s before-step question, clearing a latched fault) are published as
        ``confirm_requested`` events; answer them with the session's ``answer``."""
        from seqrun.errors import SequenceInvalid, UserInputError
        from seqrun.sequence.checks import check_from_arm
        from seqrun.sequence.loader import load_sequence
        from seqrun.sequence.validation import validate_sequence
        from seqrun.service.campaign_records import record_run
        from seqrun.service.checking import override_notes
        from seqrun.service.questions import SessionAttended
        from seqrun.service.runlog import prepare_run_folder

        s = self._session
        speed = finite(speed, "speed")
        if not 0 < speed <= 1:
            raise Refused(f"speed {speed:g} must lie in (0, 1]")
        if command_mode not in (None, "ramp", "step"):
            raise Refused(f"command mode must be ramp or step, got {command_mode!r}")
        if loaded is None:
            try:
                loaded = load_sequence(Path(file), project_root=(
                    s.project.root if s.project is not None else None))
            except SequenceInvalid as exc:
                more = len(exc.errors) - 1
                raise Refused(str(exc.errors[0]) + (f" (and {more} more)" if more else "")) \
                    from None
            except UserInputError as exc:
                raise Refused(str(exc)) from None
        if (isinstance(first_step, bool) or not isinstance(first_step, int)
                or not 1 <= first_step <= len(loaded.steps)):  # `true` is not step 1
            raise Refused(f"first step {first_step!r}: the sequence has steps "
                          f"1-{len(loaded.steps)}")
        now = s.telemetry.condition()
        start = s.telemetry.joints_deg() if now.measured else None
        if first_step == 1:  # the executor checks again from the arm's measured state
            check = validate_sequence(loaded, s.arm, start, speed=speed,
                                      started=bool(s.telemetry.homed))
        elif start is None:
            raise Refused(f"run from step {first_step}: the arm's position is not measured "
                          "yet (nothing read back), so where step "
                          f"{first_step} starts is unknown")
        else:  # as `seqrun run --from N`: the arm must stand where steps 1..N-1 leave it
            check = check_from_arm(loaded, s.arm, start, first_step=first_step, speed=speed,
                                   started=bool(s.telemetry.homed), module_limits={})
        if check.errors:
            more = len(check.errors) - 1
            raise Refused(str(check.errors[0]) + (f" (and {more} more)" if more else ""))
        if s.separation is not None:  # against the other arms where they stand (and go)
            s.separation.refuse_paths("run", check.paths)
        try:
            folder = prepare_run_folder(log_dir, loaded.name, s.log_root)
        except OSError as exc:
            raise Refused(f"cannot create the run folder: {exc.strerror or exc}") from None
        try:  # what ran is what is recorded: the bytes validated, as seqrun run keeps them
            record_run(folder, loaded, s.arm_path or loaded.arm_path,
                       s.connection.description, s.zero, arm=s.arm,
                       overrides=override_notes(loaded, s.arm_path), arm_id=s.arm_id)
        except OSError as exc:
            raise Refused(f"cannot write the run record in {folder} "
                          f"({exc.strerror or exc}); nothing was sent") from None
        activity = s.activities.begin("run", {"file": str(file), "run_dir": str(folder)},
                                       by)
        s.activities.run_info = RunInfo(str(file), None, None, len(loaded.steps), str(folder),
                                        first_step=first_step)
        total = len(loaded.steps)

        def before_step(step) -> bool:
            if not step_mode:
                return True
            return s.questions.ask(f"Run step {step.number}/{total}: {step.title}?", step=True)

        def confirm(prompt: str) -> bool:
            return True if assume_yes else s.questions.ask(prompt)

        def work() -> ActivityResult:
            outcome = self.run_loaded(loaded, log_dir=folder, speed=speed,
                                      first_step=first_step, command_mode=command_mode,
                                      confirm=confirm, before_step=before_step,
                                      confirm_clear_latched=(
                                          None if s.connection.is_simulator
                                          else lambda q: s.questions.ask(q)),
                                      html_report=html_report, file=str(file),
                                      bus_held=True,
                                      # never assume_yes: only a person answers these
                                      attended=SessionAttended(s.questions))
            result = activity_result("run", outcome.result, run_dir=folder)
            try:
                s.telemetry.poll_once()
            except Exception:  # noqa: BLE001
                pass
            return result

        return s.activities.launch(activity, work, background=True)

    def run_loaded(self, loaded, *, log_dir: Path | None, speed: float = 1.0,
                   first_step: int = 1, command_mode: str | None = None,
                   confirm: Callable[[str], bool] | None = None,
                   before_step: Callable | None = None,
                   confirm_clear_latched: Callable[[str], bool] | None = None,
                   on_executor: Callable | None = None, run_control=None, requests=None,
                   warn: Callable[[str], None] | None = None, meta: dict | None = None,
                   html_report: bool = True, file: str | None = None,
                   bus_held: bool = False, cycle_hz: float | None = None,
                   record_zero: Callable[[str], Any] | None = None, part: Any = None,
                   attended: Any = None):
        """Run an already loaded and checked sequence on the caller's thread with the
        session's driver and event hub; returns the runner's outcome (result, report, run
        folder). This is how ``seqrun run`` runs (its prompts are the terminal's own); faces
        that answer questions through events use :meth:`run_sequence`. ``record_zero``:
        what a power_off step calls to record the pose the arm is switched off in;
        ``run_control``: the run's :class:`~seqrun.service.run_control.RunControl`
        (``seqrun status|halt`` from another terminal), attached to the run's executor;
        ``part``: one arm's part of a campaign run (:mod:`seqrun.service.arm_part`);
        ``attended``: who answers signed confirms and breakpoints
        (:class:`~seqrun.steps.context.AttendedQuestions`; None: nobody, they end the run)."""
        from seqrun.service.runner import run_sequence as run_with_log
        from seqrun.stop_requests import StopRequests

        s = self._session
        requests = requests if requests is not None else StopRequests()

        def hook(executor) -> None:
            s.activities.adopt(executor)
            if s.zero is not None:  # for the log and any face
                executor.emit("zero_reference", **s.zero.as_dict())
            executor.record_zero = record_zero
            executor.attended = attended
            if run_control is not None:  # `seqrun status|halt` from another terminal
                run_control.attach(executor)
            if on_executor is not None:
                on_executor(executor)

        def go():
            return run_with_log(loaded, s.arm, s.connection, log_dir=log_dir, file=file,
                                speed=speed, first_step=first_step,
                                command_mode=command_mode, cycle_hz=cycle_hz,
                                confirm=confirm, before_step=before_step,
                                on_executor=hook, confirm_clear_latched=confirm_clear_latched,
                                meta=meta, html_report=html_report, requests=requests,
                                warn=warn, driver=s.driver, events=s.events, part=part)

        if bus_held:  # run_sequence's worker: the activity is registered already
            return go()
        activity = s.activities.begin("run", {"file": file or loaded.file,
                                              "run_dir": str(log_dir)})
        s.activities.run_info = RunInfo(file or loaded.file, None, None, len(loaded.steps),
                                        str(log_dir) if log_dir is not None else None,
                                        first_step=first_step)
        result = ActivityResult("run", "failed", EXIT_FAULT_CODE, "interrupted")
        try:
            with s.activities.bus:
                outcome = go()
            result = activity_result("run", outcome.result, run_dir=log_dir)
            return outcome
        finally:
            s.activities.end(activity, result)

    # ------------------------------------------------------------------ the run under way
    def pause(self) -> None:
        """Pause the run: the step under way finishes, then the run holds before the next
        one (``run_paused``), the arm at rest; :meth:`resume` goes on."""
        executor = self._running_executor("pause")
        executor.pause()

    def resume(self, timeout_s: float = RESUME_ANSWER_S) -> None:
        """Go on after a pause, once the run has validated the rest of the sequence from
        the arm's measured pose; Refused with the reason when that fails (the run stays
        paused). A pause not taken yet (its step still runs) is withdrawn."""
        executor = self._running_executor("resume")
        if self._session.telemetry.halted() is not None:
            raise Refused("resume: the arm was halted; nothing restarts it")
        ask = executor.resume()
        if not ask.wait(timeout_s):
            raise Refused(f"resume: the run did not answer within {timeout_s:g} s; "
                          "it stays paused")
        if ask.refused is not None:
            raise Refused(f"resume refused: {ask.refused}")
        if not self._session.activities.paused:
            self._session.activities.pause_withdrawn()

    def _running_executor(self, what: str):
        activities = self._session.activities
        activity, executor = activities.current, activities.executor
        if activity is None or activity.kind != "run" or executor is None:
            raise Refused(f"{what}: no sequence is running")
        return executor
