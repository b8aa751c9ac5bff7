"""The arms of a campaign running their tracks together: one executor per arm, one thread
each, the named events between them, and one arm's fault halting the others.

Every arm runs its track (:mod:`seqrun.sequence.arm_tracks`) through
:func:`seqrun.service.runner.run_sequence` on its own connection and driver, exactly as a
one-arm run does (the preflight, the checks every cycle, the Halt on a fault); the
``signal``/``wait_for`` steps meet on an :class:`EventBoard`. When an arm's run ends
with a fault (or an operator's halt), the others are halted too, confirmed each by its
own executor, unless the campaign says ``on_fault = "halt_faulted"``: then only the
faulted arm is halted, and another arm goes on only when its remaining planned motion is
clear of the faulted arm where it stopped (else it is halted too); those that go on do so
until they would wait for it (they fault there), and the report says so. Every control
cycle of every arm checks it against the others from their measured joints and stopping
distances (:mod:`seqrun.service.arm_separation`): too close, both are halted. The dry
run is the same on simulated buses at one virtual time
(:class:`~seqrun.clock.LockstepClock`).
"""

from __future__ import annotations

import functools
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from seqrun.results import EXIT_OK, RunResult

__all__ = ["ArmOutcome", "ArmsOutcome", "EventBoard", "OTHER_ARM_FAULT", "on_fault_of",
           "open_sessions", "run_arms_live", "run_tracks"]

#: The stop cause of an arm halted because another arm faulted.
OTHER_ARM_FAULT = "other_arm_fault"


class EventBoard:
    """The named events of one campaign run (thread-safe): which have been signalled,
    which arm would signal each, which arms have ended."""

    def __init__(self, signallers: Mapping[str, str]) -> None:
        self._lock = threading.Lock()
        self._fired: dict[str, str] = {}
        self._ended: dict[str, str] = {}
        #: event -> the arm whose track signals it
        self._signallers = dict(signallers)

    def for_arm(self, arm_id: str) -> _ArmEvents:
        return _ArmEvents(self, arm_id)

    def signal(self, arm_id: str, name: str) -> None:
        with self._lock:
            self._fired.setdefault(name, arm_id)

    def fired(self, name: str) -> bool:
        return name in self._fired

    def never(self, name: str) -> str | None:
        with self._lock:
            if name in self._fired:
                return None
            arm = self._signallers.get(name)
            if arm is None:
                return "no arm signals it"
            if arm in self._ended:
                return f"arm {arm} has ended ({self._ended[arm]}) without signalling it"
            return None

    def ended(self, arm_id: str, how: str) -> None:
        with self._lock:
            self._ended[arm_id] = how


class _ArmEvents:
    """One arm's face of the board (:class:`seqrun.steps.context.ArmEvents`)."""

    def __init__(self, board: EventBoard, arm_id: str) -> None:
        self.board, self.arm_id = board, arm_id

    def signal(self, name: str) -> None:
        self.board.signal(self.arm_id, name)

    def fired(self, name: str) -> bool:
        return self.board.fired(name)

    def never(self, name: str) -> str | None:
        return self.board.never(name)


@dataclass
class ArmOutcome:
    arm_id: str
    result: RunResult
    outcome: Any = None          # RunOutcome
    #: Halted because another arm faulted (which one).
    halted_for: str | None = None


@dataclass
class ArmsOutcome:
    """Every arm's result; the run's exit code is the worst of them."""

    arms: dict[str, ArmOutcome]
    on_fault: str
    first_fault: str | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def exit_code(self) -> int:
        codes = [a.result.exit_code for a in self.arms.values()]
        bad = [c for c in codes if c != EXIT_OK]
        return max(bad) if bad else EXIT_OK

    @property
    def passed(self) -> bool:
        return self.exit_code == EXIT_OK


def on_fault_of(project: Any) -> str:
    """The campaign's ``on_fault`` (seqrun.toml ``[campaign]``; default ``halt_all``)."""
    config = getattr(project, "config", None)
    return config.campaign.on_fault if config is not None else "halt_all"


def signallers(tracks: Mapping[str, Any]) -> dict[str, str]:
    """event -> the arm whose track signals it."""
    return {step.params.event: arm for arm, loaded in tracks.items()
            for step in loaded.steps if step.kind == "signal"}


def run_tracks(tracks: Mapping[str, Any], arms: Mapping[str, Any],
               connections: Mapping[str, Any], *, dry_run: bool, on_fault: str = "halt_all",
               log_dirs: Mapping[str, Path | None] | None = None,
               on_executor: Callable[[str, Any], None] | None = None,
               clock_views: Mapping[str, Any] | None = None,
               before_run: Callable[[str], None] | None = None,
               requests_by_arm: Mapping[str, Any] | None = None,
               runner: Callable[..., Any] | None = None,
               parts: Mapping[str, Any] | None = None,
               bases: Mapping[str, Any] | None = None,
               **run: Any) -> ArmsOutcome:
    """Run every arm's track on its connection, each on a thread of its own (see the
    module doc). ``clock_views``: each arm's :class:`~seqrun.clock.LockstepView` (the dry
    run), left when its run ends. ``before_run(arm_id)``: on the arm's thread before its
    run (the dry run's start-up of ``--started``). ``requests_by_arm``: each arm's
    stop-request inbox (the signal handlers post to every one). ``runner(arm_id, loaded,
    **options)``: how one arm's run is made (default :func:`run_sequence` on its
    connection; ``seqrun run``: the arm's session). ``parts``: each arm's
    :class:`~seqrun.service.arm_part.ArmPart` (the run's one time base and run.mcap).
    ``bases``: each arm's base frame (4x4) in the facility frame (default: the campaign's
    ``[arms.ID] base``). ``run``: further options."""
    from seqrun.service.arm_separation import Separation, bases_of_project, remaining_plan
    from seqrun.service.runner import run_sequence

    board = EventBoard(signallers(tracks))
    executors: dict[str, Any] = {}
    outcomes: dict[str, ArmOutcome] = {}
    halted_for: dict[str, str] = {}
    lock = threading.Lock()
    state: dict[str, str | None] = {"first_fault": None}
    errors: dict[str, BaseException] = {}
    #: What halt_faulted decided for the other arms (said in the outcome's notes).
    went_on: list[str] = []
    if bases is None:
        project = getattr(next(iter(tracks.values()), None), "project", None)
        bases = bases_of_project(project, tracks)
    separation = Separation({a: arms[a] for a in tracks}, bases) if len(tracks) > 1 \
        else None

    def hook(arm_id: str):
        def attach(executor) -> None:
            executor.sync = board.for_arm(arm_id)
            if separation is not None:
                executor.separation = separation.watch(
                    arm_id, halt=executor.halt,
                    plan=functools.partial(remaining_plan, executor))
            with lock:
                executors[arm_id] = executor
                stop = state["first_fault"] is not None and on_fault == "halt_all"
            if stop:
                executor.halt(f"arm {state['first_fault']} faulted", OTHER_ARM_FAULT)
                halted_for[arm_id] = str(state["first_fault"])
            if on_executor is not None:
                on_executor(arm_id, executor)
        return attach

    def one(arm_id: str) -> None:
        view = (clock_views or {}).get(arm_id)
        try:
            if before_run is not None:
                before_run(arm_id)
            options = dict(run, log_dir=(log_dirs or {}).get(arm_id),
                           on_executor=hook(arm_id),
                           requests=(requests_by_arm or {}).get(arm_id),
                           part=(parts or {}).get(arm_id))
            if runner is not None:
                outcome = runner(arm_id, tracks[arm_id], **options)
            else:
                outcome = run_sequence(tracks[arm_id], arms[arm_id], connections[arm_id],
                                       dry_run=dry_run, **options)
            result = outcome.result
            outcomes[arm_id] = ArmOutcome(arm_id, result, outcome)
        except BaseException as exc:  # noqa: BLE001 - said in the outcome; the others halt
            errors[arm_id] = exc
            result = None
        finally:
            how = "passed" if result is not None and result.exit_code == EXIT_OK \
                else (result.status if result is not None else "an error")
            board.ended(arm_id, how)
            if result is None or result.exit_code != EXIT_OK:
                with lock:
                    first = state["first_fault"] is None
                    if first:
                        state["first_fault"] = arm_id
                    others = dict(executors)
                if first and on_fault == "halt_all":
                    for other, executor in others.items():
                        if other != arm_id and other not in outcomes:
                            halted_for[other] = arm_id
                            executor.halt(f"arm {arm_id} faulted", OTHER_ARM_FAULT)
                elif on_fault != "halt_all" and separation is not None \
                        and arm_id in others:
                    _halt_unless_clear(separation, arm_id, others, outcomes, halted_for,
                                       went_on)
            if separation is not None:
                separation.release(arm_id)
            if view is not None:
                view.leave()

    threads = [threading.Thread(target=one, args=(arm_id,), name=f"seqrun-arm-{arm_id}",
                                daemon=True) for arm_id in tracks]
    for thread in threads:
        thread.start()
    for thread in threads:
        while thread.is_alive():  # a signal handler runs between the waits
            thread.join(0.1)
    if errors:
        arm_id, exc = next(iter(errors.items()))
        raise exc
    for arm_id, why in halted_for.items():
        if arm_id in outcomes and outcomes[arm_id].result.exit_code != EXIT_OK:
            outcomes[arm_id].halted_for = why
    result = ArmsOutcome({a: outcomes[a] for a in tracks}, on_fault, state["first_fault"])
    result.notes += went_on
    if separation is not None and separation.tripped is not None:
        result.notes.append(separation.tripped)
    if state["first_fault"] is not None:
        first = state["first_fault"]
        if on_fault == "halt_all":
            result.notes.append(f"arm {first} faulted: every arm was halted "
                                "(on_fault = halt_all)")
        else:
            also = [a for a, why in halted_for.items() if why == first]
            if also:
                result.notes.append(f"arm {first} faulted: arm {first} was halted, and arm "
                                    f"{', '.join(also)} too (on_fault = halt_faulted in "
                                    "seqrun.toml, but its remaining motion was not clear of "
                                    f"arm {first} where it stopped)")
            else:
                result.notes.append(f"arm {first} faulted: only arm {first} was halted "
                                    "(on_fault = halt_faulted in seqrun.toml); the other "
                                    "arms went on")
    return result


def _halt_unless_clear(separation: Any, faulted: str, executors: Mapping[str, Any],
                       outcomes: Mapping[str, Any], halted_for: dict[str, str],
                       notes: list[str]) -> None:
    """``on_fault = "halt_faulted"``: the faulted arm stands where its confirmed Halt left
    it; every other arm still running goes on only if its remaining planned motion is
    clear of it there, else it is halted too (:meth:`Separation.clear_of_stopped`)."""
    last = getattr(executors[faulted], "last", None)
    if last is not None:
        separation.stopped(faulted, last.user_deg)
    for other, executor in executors.items():
        if other == faulted or other in outcomes:
            continue
        clear, why = separation.clear_of_stopped(other, faulted)
        if clear:
            notes.append(f"arm {other} went on: {why}")
            continue
        halted_for[other] = faulted
        notes.append(f"arm {other} halted too: {why}")
        executor.halt(f"arm {faulted} faulted and {why}", OTHER_ARM_FAULT)


def open_sessions(tracks: Mapping[str, Any], arms: Mapping[str, Any],
                  connections: Mapping[str, Any], zeros: Mapping[str, Any] | None = None
                  ) -> dict[str, Any]:
    """An arm session per arm of a campaign's run (on its connection, which it leaves open;
    the caller closes the sessions): what :func:`run_arms_live` runs each arm in, opened
    before it when a face watches them from the start (``seqrun run --foxglove``)."""
    from seqrun.service.session import ArmSession

    return {a: ArmSession(arms[a], connections[a], project=tracks[a].project,
                          zero=(zeros or {}).get(a), status_hz=0, own_connection=False,
                          arm_id=a)
            for a in tracks}


def run_arms_live(tracks: Mapping[str, Any], arms: Mapping[str, Any],
                  connections: Mapping[str, Any], *, controls: Mapping[str, Any],
                  on_event: Callable[[str, Any], None] | None = None,
                  zeros: Mapping[str, Any] | None = None,
                  record_zero: Mapping[str, Any] | None = None,
                  on_idle: Callable[[str, float], None] | None = None,
                  sessions: Mapping[str, Any] | None = None,
                  confirms: Mapping[str, Callable[[str], bool]] | None = None,
                  **options: Any) -> ArmsOutcome:
    """:func:`run_tracks` for ``seqrun run``: every arm runs in an arm session of its own
    (:class:`~seqrun.service.session.ArmSession`, its driver, zero and activities, as one
    arm's run), each arm's run control (``seqrun status|halt`` from another terminal, None
    where its bus has no claim) follows its run, and ``on_event(arm_id, event)`` gets
    every typed event of every arm (on that arm's loop thread: it must be quick).
    ``record_zero``: per arm, what records its zero at a power_off step (None: the
    simulator). ``on_idle(arm_id, slack)``: each arm's loop's idle hook (a live view
    drawn in the slack before that arm's next cycle). ``sessions``: the arms' sessions
    already open (the console's; left open), else one is made per arm for the run;
    ``confirms``: each arm's confirm (its questions, instead of one ``confirm`` for every
    arm)."""
    own = sessions is None
    if sessions is None:
        sessions = open_sessions(tracks, arms, connections, zeros)
    if on_idle is not None:
        for arm_id, session in sessions.items():
            session.add_idle_hook(functools.partial(on_idle, arm_id))

    def attach(arm_id: str, executor: Any) -> None:
        control = controls.get(arm_id)
        if control is not None:
            control.attach(executor)
        if on_event is not None:
            executor.listeners.append(lambda event: on_event(arm_id, event))

    def runner(arm_id: str, loaded: Any, **run: Any) -> Any:
        zero = (zeros or {}).get(arm_id)
        if confirms is not None:
            run["confirm"] = confirms[arm_id]
        return sessions[arm_id].run_loaded(
            loaded, record_zero=(record_zero or {}).get(arm_id),
            meta={"arm_id": arm_id, **({"zero": zero.as_dict()} if zero is not None else {})},
            **run)

    try:
        return run_tracks(tracks, arms, connections, on_executor=attach, runner=runner,
                          dry_run=False, **options)
    finally:
        for session in sessions.values() if own else ():
            session.close()
