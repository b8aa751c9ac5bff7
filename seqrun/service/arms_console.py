"""The arm sessions of one face that serves several arms at once (``seqrun console`` in a
campaign with ``[arms.*]``): one :class:`~seqrun.service.session.ArmSession` per arm, each
with its own bus, driver and zero reference, one control desk for all of them (one operator
commands the whole console), and one STOP that halts every arm and confirms each.

The STOP halts the arms at the same time, each from a thread of its own: an arm whose Halt
is not confirmed (a module that does not answer, a bus gone) does not delay the Halt of
the others, and an error halting one arm is that arm's "not confirmed", never the others'.
"""

from __future__ import annotations

import threading
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from seqrun.service.control import ControlDesk

__all__ = ["ArmHalt", "ArmSessions", "ArmsHalt", "ArmsRun"]


@dataclass(frozen=True)
class ArmHalt:
    """One arm's part of a STOP: sent, confirmed (every module read back HALTED), the
    operator's line, and which modules did not confirm."""

    arm_id: str
    sent: bool
    confirmed: bool
    message: str
    modules_not_halted: tuple[int, ...] = ()

    def as_dict(self) -> dict[str, Any]:
        return {"halt_sent": self.sent, "halt_confirmed": self.confirmed,
                "modules_not_halted": list(self.modules_not_halted), "message": self.message}


@dataclass(frozen=True)
class ArmsHalt:
    """Every arm's Halt; confirmed when every arm's was."""

    arms: dict[str, ArmHalt]

    @property
    def confirmed(self) -> bool:
        return all(a.confirmed for a in self.arms.values())

    @property
    def not_confirmed(self) -> list[str]:
        return [a for a, h in self.arms.items() if not h.confirmed]

    def describe(self) -> str:
        """One line: each arm, halted or not."""
        parts = [f"arm {a}: {h.message}" if h.confirmed else f"arm {a}: STOP FAILED: "
                 f"{h.message}" for a, h in self.arms.items()]
        head = "every arm halted" if self.confirmed else \
            f"STOP FAILED for arm {', '.join(self.not_confirmed)}: use the emergency stop"
        return f"{head} ({'; '.join(parts)})"

    def as_dict(self) -> dict[str, Any]:
        return {"halt_sent": all(h.sent for h in self.arms.values()),
                "halt_confirmed": self.confirmed, "not_confirmed": self.not_confirmed,
                "arms": {a: h.as_dict() for a, h in self.arms.items()},
                "message": self.describe()}


@dataclass
class ArmsRun:
    """A sequence of several arms run from a face: its name, run folder, arms, who started
    it; ``outcome`` (:class:`~seqrun.service.arms_run.ArmsOutcome`) once it ended, or
    ``error`` (a bug: every arm was halted by its own run)."""

    name: str
    folder: Path
    arms: tuple[str, ...]
    by: str | None = None
    outcome: Any = None
    error: str | None = None
    #: What went wrong with its records (run.mcap, arms.json); the run went on.
    warnings: list[str] = field(default_factory=list)
    finished: threading.Event = field(default_factory=threading.Event)

    @property
    def done(self) -> bool:
        return self.finished.is_set()

    def as_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"name": self.name, "run_dir": str(self.folder),
                               "arms": list(self.arms), "by": self.by, "done": self.done,
                               "error": self.error, "warnings": list(self.warnings)}
        if self.outcome is not None:
            out.update(exit_code=self.outcome.exit_code, first_fault=self.outcome.first_fault,
                       notes=list(self.outcome.notes),
                       results={a: {"status": o.result.status, "exit_code": o.result.exit_code,
                                    "message": o.result.message,
                                    "halted_because_arm": o.halted_for}
                                for a, o in self.outcome.arms.items()})
        return out


class ArmSessions:
    """The sessions of several arms, in the campaign's order (``sessions``: arm id ->
    session). The sessions share one :class:`ControlDesk` (its events on the first arm's
    hub). :meth:`close` closes every session (a controlled stop of anything moving)."""

    def __init__(self, sessions: Mapping[str, Any],
                 bases: Mapping[str, Any] | None = None) -> None:
        if not sessions:
            raise ValueError("no arm session")
        self.sessions = dict(sessions)
        #: Each arm's base in the facility frame (seqrun.toml ``[arms.ID] base``; missing
        #: or None: the facility frame), for the records of a run.
        self.bases = dict(bases or {})
        first = next(iter(self.sessions.values()))
        self.control = ControlDesk(publish=first.publish, clock=first.clock.now,
                                   stop_motion=self.stop_motion_of)
        for session in self.sessions.values():
            session.control = self.control
        from seqrun.service.arm_separation import attach_sessions

        #: The arms against each other: every motion of a face checked before it is sent,
        #: every cycle of a session's executor (seqrun/service/arm_separation.py).
        self.separation = attach_sessions(self.sessions, self.bases)
        #: The campaign run under way or last (:meth:`run_sequence`).
        self.run: ArmsRun | None = None
        self._run_lock = threading.Lock()

    @property
    def arm_ids(self) -> tuple[str, ...]:
        return tuple(self.sessions)

    def __getitem__(self, arm_id: str) -> Any:
        return self.sessions[arm_id]

    def halt(self, reason: str = "STOP") -> ArmsHalt:
        """Halt every arm at once (a thread each) and confirm each (see the module doc)."""
        results: dict[str, ArmHalt] = {}

        def one(arm_id: str, session: Any) -> None:
            try:
                result = session.halt(reason)
                names = dict(zip(session.arm.module_ids, session.arm.joint_names))
                results[arm_id] = ArmHalt(arm_id, result.sent, result.confirmed,
                                          result.describe(names),
                                          tuple(result.modules_unconfirmed))
            except Exception as exc:  # noqa: BLE001 - this arm's failure, said; others go on
                results[arm_id] = ArmHalt(arm_id, False, False,
                                          f"the Halt failed ({type(exc).__name__}: {exc}): "
                                          "use the emergency stop")

        threads = [threading.Thread(target=one, args=(a, s), name=f"halt-arm-{a}", daemon=True)
                   for a, s in self.sessions.items()]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
        return ArmsHalt({a: results[a] for a in self.sessions})

    # ------------------------------------------------------------------ a campaign run
    def run_sequence(self, file: Path, *, speed: float = 1.0, by: str | None = None,
                     html_report: bool = True) -> ArmsRun:
        """Validate ``file`` (a sequence that names the arms) as ``seqrun run`` does
        (:func:`seqrun.service.arms_check.check_arms_sequence`: each arm, the arms against
        each other), then run it on these sessions in the background through
        :func:`seqrun.service.arms_run.run_arms_live`, the service ``seqrun run`` uses for
        several arms: one part of the run folder per arm, each arm's events on its
        session's hub, a confirm step asked as the arm's question (answered through its
        session). :class:`~seqrun.errors.Refused`: not valid, or an arm busy."""
        from seqrun.errors import Refused, UserInputError
        from seqrun.service.arms_check import check_arms_sequence
        from seqrun.service.arms_records import ArmOfRun, ArmsRunRecords
        from seqrun.service.arms_run import on_fault_of, run_arms_live
        from seqrun.service.runlog import prepare_run_folder

        if not 0 < speed <= 1:
            raise Refused(f"speed {speed:g} must lie in (0, 1]")
        with self._run_lock:
            busy = [a for a, s in self.sessions.items() if s.activity is not None]
            if busy or (self.run is not None and not self.run.done):
                raise Refused(f"run: arm {', '.join(busy) or '?'} is busy; stop it first")
            first = next(iter(self.sessions.values()))
            try:
                check = check_arms_sequence(Path(file), first.project, speed=speed,
                                            dry_run=False)
            except UserInputError as exc:
                raise Refused(str(exc)) from None
            if check.errors:
                more = len(check.errors) - 1
                raise Refused(str(check.errors[0]) + (f" (and {more} more)" if more else ""))
            tracks = check.tracks.tracks
            from seqrun.service.attended import first_attended

            for arm_id, track in tracks.items():  # each arm's thread has no one to ask them
                found = first_attended(track.steps, check.hazards.get(arm_id))
                if found is not None:
                    raise Refused(f"run: arm {arm_id}: {found}: not in a run of several arms "
                                  "yet")
            missing = [a for a in tracks if a not in self.sessions]
            if missing:
                raise Refused(f"run: the sequence names arm {', '.join(missing)}, which this "
                              f"console does not serve (arms {', '.join(self.sessions)})")
            sessions = {a: self.sessions[a] for a in tracks}
            warnings: list[str] = []
            try:  # the records of seqrun run's (seqrun/service/arms_records.py)
                # where this console's runs go (its --log-dir), as a run of one arm of it
                folder = prepare_run_folder(None, check.tracks.name, first.log_root)
                records = ArmsRunRecords.start(
                    folder, tracks,
                    {a: ArmOfRun(s.arm, s.zero, s.arm_path or tracks[a].arm_path,
                                 s.connection.description, s.connection.is_simulator,
                                 self.bases.get(a)) for a, s in sessions.items()},
                    first.connection.clock, project=check.tracks.project,
                    warn=warnings.append)
            except (OSError, UserInputError) as exc:
                raise Refused(f"cannot write the run folder ({exc}); nothing was sent") \
                    from None
            run = ArmsRun(check.tracks.name, folder, tuple(tracks), by, warnings=warnings)

            def work() -> None:
                try:
                    run.outcome = run_arms_live(
                        tracks, {a: s.arm for a, s in sessions.items()},
                        {a: s.connection for a, s in sessions.items()}, controls={},
                        sessions=sessions, zeros={a: s.zero for a, s in sessions.items()},
                        confirms={a: s.questions.ask for a, s in sessions.items()},
                        on_fault=on_fault_of(check.tracks.project), speed=speed,
                        html_report=html_report, file=str(file), **records.run_options())
                except Exception as exc:  # noqa: BLE001 - every arm halted by its run; said
                    run.error = f"{type(exc).__name__}: {exc}"
                finally:
                    try:  # run.mcap ended and arms.json written before the run is done
                        records.close_mcap()
                        if run.outcome is not None:
                            records.finish(check, run.outcome)
                    except Exception as exc:  # noqa: BLE001 - the records' trouble, said
                        warnings.append(f"the run's records: {type(exc).__name__}: {exc}")
                    finally:
                        run.finished.set()

            self.run = run
            threading.Thread(target=work, name="console-arms-run", daemon=True).start()
            return run

    def stop_motion_of(self, client: Any) -> str | None:
        """End what ``client`` started on every arm (a controlled stop): the campaign run
        it started, and each arm's motion (:meth:`ArmSession.stop_motion_of`)."""
        done: list[str] = []
        run = self.run
        if run is not None and not run.done and getattr(run, "by", None) == client.name:
            self.abort(f"{client.name} no longer holds control")
            done.append("the run of several arms stopped (controlled stop)")
        for arm_id, session in self.sessions.items():
            stopped = session.stop_motion_of(client)
            if stopped:
                done.append(f"arm {arm_id}: {stopped}")
        return "; ".join(done) or None

    def abort(self, reason: str = "operator abort") -> None:
        """A controlled stop of whatever moves on every arm."""
        for session in self.sessions.values():
            session.abort(reason)

    def close(self) -> None:
        """Close every session, each even when another's close fails."""
        errors: list[BaseException] = []
        for session in self.sessions.values():
            try:
                session.close()
            except Exception as exc:  # noqa: BLE001 - the other arms are still closed
                errors.append(exc)
        if errors:
            raise errors[0]
