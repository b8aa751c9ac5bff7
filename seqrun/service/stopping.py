"""Stopping the arm: the operator's STOP (a confirmed Halt) and abort (a controlled stop).

:meth:`Stopping.halt` **never waits behind anything**: it posts a Halt request to the
running activity's stop-request inbox (a deque append), sends the Halt broadcast from the
caller's thread through the driver (``halt_now(wait=False)``: it takes no lock a run
holds), withdraws open questions and only then confirms, by the activity's own emergency
Halt or by reading every module back. Part of the arm session
(:mod:`seqrun.service.session`).
"""

from __future__ import annotations

from typing import Any

from seqrun.drivers.base import HaltConfirmation

#: halt() waits at most this long (s) for an activity to confirm its Halt.
HALT_CONFIRM_WAIT_S = 5.0


class Stopping:
    """STOP and abort of one session (its ``driver``, ``arm``, ``activities``,
    ``telemetry``, ``questions`` and ``publish``)."""

    def __init__(self, session: Any) -> None:
        self._session = session

    def halt(self, reason: str = "STOP") -> HaltConfirmation:
        """Halt broadcast now from this thread, stop any activity, confirm by reading every
        module back. Never waits behind a lock, a run or a queue before the broadcast."""
        from seqrun.errors import BusError

        s = self._session
        activities = s.activities
        # The running activity's inbox first (a deque append: no lock, no wait), so that
        # the loop takes the modules' HALTED state for the operator's Halt (exit 130),
        # then the broadcast from this thread, whatever holds the bus.
        executor, activity = activities.executor, activities.current
        if executor is not None:
            executor.halt(reason)
        sent_error = None
        try:
            s.driver.halt_now(wait=False)
        except BusError as exc:
            sent_error = str(exc)
        s.telemetry.mark_halted(reason)
        s.questions.withdraw()
        result: HaltConfirmation | None = None
        if activity is not None:
            try:
                activity.wait(timeout=HALT_CONFIRM_WAIT_S)
            except TimeoutError:
                pass
            if executor is not None and executor.halt_result is not None:
                result = executor.halt_result
        modules = tuple(s.arm.module_ids)
        if result is None:
            if activities.bus.acquire(timeout=HALT_CONFIRM_WAIT_S):
                try:
                    result = s.driver.halt_and_confirm()
                    if result.confirmed:
                        s.telemetry.poll_once()
                finally:
                    activities.bus.release()
            else:
                result = HaltConfirmation("halt", modules, sent=sent_error is None,
                                          unconfirmed={m: "not read back" for m in modules},
                                          error="the activity did not hand the bus back "
                                                "in time to read the modules")
        if sent_error is not None and not result.sent:
            result = HaltConfirmation("halt", modules, sent=False,
                                      unconfirmed={m: "no Halt sent" for m in modules},
                                      attempts=result.attempts, error=sent_error)
        s.publish("session_halt", reason=reason, halt_sent=result.sent,
                  halt_confirmed=result.confirmed,
                  modules_not_halted=list(result.modules_unconfirmed),
                  message=result.describe(self._names()))
        return result

    def halt_dict(self, reason: str = "STOP") -> dict[str, Any]:
        """:meth:`halt` as a JSON-ready dict (the control socket's ``halt`` op)."""
        from seqrun.service.status import API_VERSION

        result = self.halt(reason)
        return {"v": API_VERSION, **result.as_dict(), "message": result.describe(self._names())}

    def abort(self, reason: str = "operator abort") -> None:
        """Controlled stop of whatever moves (run, move, jog); the activity ends (130 for a
        run or move; a jog ends normally). As with Ctrl-C, a second abort of a run or move
        is a Halt."""
        activities = self._session.activities
        executor, deadman = activities.executor, activities.deadman
        if deadman is not None:
            deadman.release(reason)  # at most one abort per jog
        elif executor is not None:
            executor.abort(reason)
        self._session.questions.withdraw()

    def _names(self) -> dict[int, str]:
        arm = self._session.arm
        return dict(zip(arm.module_ids, arm.joint_names))


class ControlHandler:
    """What a control socket (:mod:`seqrun.service.control_socket`) serves for a session:
    ``status_dict()`` and ``halt(reason) -> dict``, in the socket's shapes (the same as a
    run's: ``seqrun status`` and ``seqrun halt`` read either the same way)."""

    def __init__(self, session: Any) -> None:
        self._session = session

    def status_dict(self) -> dict[str, Any]:
        from seqrun.service.control_socket import reading_row

        status = self._session.status()
        stale = status.stale or status.updated_at is None
        joints = [reading_row(j.name, j.module, j.position_deg, j.velocity_deg_s,
                              "|".join(j.flags) or None, j.fault,
                              stale or j.position_deg is None)
                  for j in status.joints]
        ee = None
        if status.end_effector_mm is not None:
            ee = {"position_mm": [round(v, 3) for v in status.end_effector_mm],
                  "rpy_deg": [round(v, 3) for v in status.end_effector_rpy_deg or ()]}
        run = status.run
        return {"joints": joints, "end_effector": ee, "activity": status.activity,
                "step": ({"step": run.step, "label": run.label} if run is not None else None),
                "bus": status.bus, "zero_reference": status.zero_reference}

    def halt(self, reason: str) -> dict[str, Any]:
        from seqrun.service.control_socket import halt_reply

        arm = self._session.arm
        return halt_reply(self._session.halt(reason), dict(zip(arm.module_ids, arm.joint_names)),
                          "the console's session")
