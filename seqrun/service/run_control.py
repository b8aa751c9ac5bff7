"""``seqrun run`` as the owner of a shared bus: the control socket's handler
(``seqrun status`` and ``seqrun halt`` from another terminal), and the watch for another
master's frames that halts the run.

Until an arm session (seqrun/service/session.py) owns the bus, this adapts what a run
has: the executor's events (the last measurement) for ``status``, its stop-request inbox
and Halt confirmation for ``halt``. Everything here is called from the control socket's
threads or cheaply from the executor's listeners: it never blocks the control loop.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from typing import Any

from seqrun.stop_requests import FOREIGN_MASTER, REMOTE_HALT, StopRequests

#: How long a ``halt`` request waits for the run's own Halt confirmation before this
#: process confirms it itself, s (the loop acts within a cycle; a confirmation with a
#: silent module takes about 0.6 s).
HALT_WAIT_S = 2.0
#: Measured velocity: the slope over this much of the last readings, s.
VELOCITY_WINDOW_S = 0.1


class RunControl:
    """The control handler of a running ``seqrun run`` (``status_dict``, ``halt``)."""

    def __init__(self, arm, requests: StopRequests, description: str = "") -> None:
        self.arm = arm
        self.requests = requests
        self.description = description
        self.executor = None
        self.finished = threading.Event()
        self._readings: deque[tuple[float, list[float]]] = deque(maxlen=64)
        self._states: list[Any] = []
        self._words: dict[str, str] = {}
        self._step: dict[str, Any] | None = None
        self._claim = None

    # ------------------------------------------------------------------ wiring
    @classmethod
    def serve(cls, connection, arm, requests: StopRequests) -> RunControl | None:
        """Serve the control socket for the run on ``connection`` (when it holds a claim
        of a shared bus); the socket goes with the claim."""
        if connection.claim is None:
            return None
        from seqrun.service.control_socket import serve_control

        control = cls(arm, requests, connection.description)
        control._claim = connection.claim
        serve_control(connection.claim, control)
        return control

    def attach(self, executor) -> None:
        """Follow ``executor``'s events from now on."""
        self.arm = executor.arm
        self.executor = executor
        executor.listeners.append(self.on_event)

    def on_event(self, event: dict) -> None:
        """Executor listener (in the control loop: appends only)."""
        kind = event.get("type")
        if kind in ("setpoint", "measurement"):
            joints = event.get("measured_deg") or event.get("joints_deg")
            if joints is not None:
                self._readings.append((float(event["t"]), list(joints)))
            self._states = list(event.get("state") or [])
            self._words = dict(event.get("states") or {})
        elif kind == "step_started":
            self._step = {"step": event.get("step"), "label": event.get("label"),
                          "kind": event.get("kind")}
        elif kind == "run_finished":
            self.finished.set()
            # The run is over: the bus is free for the next controller while this
            # process draws its report (nothing more is sent).
            if self._claim is not None:
                self._claim.release()

    # ------------------------------------------------------------------ the handler
    def status_dict(self) -> dict:
        """What ``seqrun status`` prints, from the run's last reading (the same shape as a
        reading of the bus: joints, end effector), plus the run's activity."""
        from seqrun.drivers.registry import cycle_state
        from seqrun.service.control_socket import reading_row
        from seqrun.service.kinematics import end_effector

        readings = list(self._readings)
        joints_out = []
        last = readings[-1][1] if readings else None
        velocity = _velocities(readings)
        for k, joint in enumerate(self.arm.joints):
            short = cycle_state(self.arm, self._states[k]) if k < len(self._states) else None
            word = self._words.get(str(joint.module))
            joints_out.append(reading_row(
                joint.name, joint.module,
                None if last is None else round(float(last[k]), 4),
                None if velocity is None else round(velocity[k], 4),
                word or (short.describe() if short is not None else None),
                bool(short is not None and short.refuses_motion), last is None))
        status: dict[str, Any] = {"joints": joints_out, "end_effector": None}
        if last is not None:
            status["end_effector"] = end_effector(self.arm, last)
        status["activity"] = ("finished" if self.finished.is_set() else
                              "starting" if self.executor is None else "running")
        status["step"] = self._step
        status["bus"] = self.description
        return status

    def halt(self, reason: str) -> dict:
        """Halt the run and confirm it: the run's control loop sends the Halt at its next
        cycle and confirms it (the run then ends with exit 3); when it has not within
        :data:`HALT_WAIT_S` (it waits for an operator's answer, or has ended), this thread
        confirms through the run's driver (its Halt may come from any thread)."""
        self.requests.halt(reason, cause=REMOTE_HALT)
        deadline = time.monotonic() + HALT_WAIT_S
        while time.monotonic() < deadline and not self.finished.is_set():
            executor = self.executor
            if executor is not None and executor.halt_result is not None:
                return self._confirmation(executor.halt_result, "the run")
            time.sleep(0.005)
        executor = self.executor
        if executor is not None and executor.halt_result is not None:
            return self._confirmation(executor.halt_result, "the run")
        if executor is None or self.finished.is_set():
            return {"confirmed": False, "sent": False,
                    "error": ("the run has ended" if self.finished.is_set()
                              else "the run has not started yet")
                    + "; the Halt request stays posted"}
        # The driver's emergency stop may be called from any thread.
        return self._confirmation(executor.driver.halt_and_confirm(), "the run's process")

    def _confirmation(self, result, by: str) -> dict:
        from seqrun.service.control_socket import halt_reply

        return halt_reply(result, {j.module: j.name for j in self.arm.joints}, by)


def _velocities(readings: list[tuple[float, list[float]]]) -> list[float] | None:
    """deg/s per joint: the slope over the last :data:`VELOCITY_WINDOW_S` of readings."""
    if len(readings) < 2:
        return None
    t1, q1 = readings[-1]
    t0, q0 = readings[0]
    for t, q in reversed(readings[:-1]):
        if t1 - t >= VELOCITY_WINDOW_S:
            t0, q0 = t, q
            break
    if t1 - t0 <= 0:
        return None
    return [(b - a) / (t1 - t0) for a, b in zip(q0, q1)]


def halt_on_foreign_frames(executor, driver) -> None:
    """A request the run's driver sees on the bus that this process did not send ends the
    run: Halt, exit 3 ("another controller is on the bus (frame ...)"; a Halt broadcast is
    named as one). The request is posted like a signal's (lock-free); the loop acts on it
    within a cycle."""
    def on_foreign(frame) -> None:
        executor.halt(frame.message(), cause=REMOTE_HALT if frame.is_halt else FOREIGN_MASTER)

    driver.watch_foreign(on_foreign)

