"""Before the first step: read the arm and check the sequence again from where it stands.

The preflight reads every joint and its full state and the limits the drives hold
(MinPos/MaxPos/MaxVel/MaxAcc stay stored across runs), then validates the sequence (from
``--from N``) from the measured state with those limits: nothing moves if that fails. A
fault the modules had latched before the run is told (``latched_fault``) and, on real
hardware, cleared by a Reset step only when the operator says so (:class:`LatchedFaults`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from seqrun.events import make_event
from seqrun.arm.telemetry import joint_flags
from seqrun.execution.streaming import rounded
from seqrun.results import OperatorAbort, latched_message

if TYPE_CHECKING:
    from seqrun.drivers.base import JointState
    from seqrun.executor import Executor

#: MinPos/MaxPos the drives hold count as the arm file's within this (the float32 a drive
#: stores, 1e-5 rad).
LIMITS_MATCH_DEG = math.degrees(1e-5)


def preflight(run: Executor, loaded, first_step: int = 1):
    """Read the arm and validate ``loaded`` (from ``first_step``) from the measured state.
    Returns the ValidationResult; only reads reach the bus."""
    from seqrun.sequence.validation import validate_sequence

    arm = run.arm
    m = run.read_arm()
    states = run.read_state_words()
    run.beat()
    stored = run.driver.read_limits()
    written = all(abs(held.min_deg - j.limits_deg[0]) < LIMITS_MATCH_DEG
                  and abs(held.max_deg - j.limits_deg[1]) < LIMITS_MATCH_DEG
                  for j, held in zip(arm.joints, stored))
    module_limits = {j.name: (held.max_velocity_deg_s, held.max_acceleration_deg_s2)
                     for j, held in zip(arm.joints, stored)}
    run.limits_in_force.read_back(module_limits)
    ready = all(f.ready for f in states.values())
    run.latched.record(states)
    started = ready and written
    start_deg = {j.name: float(v) for j, v in zip(arm.joints, m.user_deg)}
    steps_before, steps_from = loaded.split_at(first_step)  # as `seqrun run --from`
    result = validate_sequence(steps_from, arm, start_deg, started=started, speed=run.speed,
                               module_limits=module_limits)
    if first_step > 1:
        before = validate_sequence(steps_before, arm)
        tol = max(1.0, 5 * arm.control.position_tolerance_deg)
        for j in arm.joints:
            expected = before.final_deg.get(j.name)
            if expected is not None and abs(expected - start_deg[j.name]) > tol:
                result.errors.append(loaded.steps[first_step - 1].location.error(
                    f"--from {first_step}: the arm is not where this step expects it: "
                    f"{j.name} at {start_deg[j.name]:.2f}°, expected {expected:.2f}° "
                    f"(after steps 1-{first_step - 1})"))
    run.validated_targets = dict(getattr(result, "targets_deg", {}))
    run.emit("preflight", start_deg=rounded(m.user_deg), homed=ready, limits_written=written,
             module_limits={n: rounded(v) for n, v in module_limits.items()},
             states={str(k): v.describe() for k, v in states.items()},
             errors=[str(e) for e in result.errors], notes=[str(n) for n in result.notes])
    if run.events.subscribers:
        # Faces get the first reading as a measurement too (not logged: the preflight
        # event holds it), its flags decoded by the driver like every other one.
        flags, fault = joint_flags(arm.joint_names, run.modules, m.short_state, states)
        now = run.clock.now()
        run.events.publish(make_event(
            "measurement", round(run.elapsed_s(), 6),
            {"joints_deg": rounded(m.user_deg),
             "state": [states[k].cycle_code if k in states else int(m.short_state[k])
                       for k in run.modules]},
            clock_s=now, flags=flags, fault=fault, source="preflight"))
    return result


class LatchedFaults:
    """Faults the modules report before the run sent anything but reads.

    :param confirm: asked before a Reset clears one (real hardware: someone may have
        pressed the emergency stop for a reason); None: not asked (simulator, dry run).
    """

    def __init__(self, run: Executor, confirm: Callable[[str], bool] | None) -> None:
        self._run = run
        self.confirm = confirm
        self.at_start: list[dict[str, Any]] = []
        self._cleared_ok = False

    def record(self, states: dict[int, JointState]) -> None:
        """Told on the terminal (event ``latched_fault``) and in the report, never cleared
        silently."""
        run = self._run
        names = dict(zip(run.modules, run.arm.joint_names))
        self.at_start = [
            {"module": m, "joint": names.get(m, "?"),
             "flags": f.fault_text, "state": f.describe()}
            for m, f in sorted(states.items()) if f.faulted]
        if self.at_start:
            run.emit("latched_fault", modules=self.at_start, message=self.message())

    def message(self) -> str:
        return latched_message(self.at_start)

    def confirm_clearing(self, modules: list[int] | None) -> None:
        """Called by a Reset step before it clears faults: on real hardware a fault that
        was latched before the run is cleared only when the operator says so (also with
        ``--yes``); declining, or no answer, ends the run as an operator abort."""
        if not self.at_start or self._cleared_ok:
            return
        affected = [e for e in self.at_start if modules is None or e["module"] in modules]
        if not affected:
            return
        run = self._run
        if self.confirm is not None:
            question = (self.message() + ". This Reset clears it. Has the cause "
                        "been checked, and may it be cleared?")
            if not run.ask_operator(self.confirm, question):
                raise OperatorAbort("operator did not clear the fault latched before the "
                                    "run; nothing was reset")
            run.emit("latched_fault_cleared", modules=[e["module"] for e in affected],
                     confirmed_by="operator")
        else:
            run.emit("latched_fault_cleared", modules=[e["module"] for e in affected],
                     confirmed_by="not asked (simulator)")
        self._cleared_ok = True
