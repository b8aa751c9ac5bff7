"""Before the first step: read the arm and check the sequence again from where it stands.

The preflight reads every joint and its full state and the limits the drives hold
(MinPos/MaxPos/MaxVel/MaxAcc stay stored across runs), then validates the sequence (from
``--from N``) from the measured state with those limits: nothing moves if that fails. A
fault the modules had latched before the run is told (:mod:`.latched`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, Protocol

from seqrun.drivers.telemetry import joint_flags
from seqrun.events import make_event
from seqrun.execution.run import rounded

if TYPE_CHECKING:
    import numpy as np

    from seqrun.arm.description import ArmDescription
    from seqrun.errors import SourceError
    from seqrun.execution.run import Run


class Findings(Protocol):
    """What a check of the sequence found (the sequence layer's ValidationResult)."""

    @property
    def errors(self) -> list[SourceError]: ...

    @property
    def notes(self) -> list[SourceError]: ...

    @property
    def targets_deg(self) -> Mapping[int, np.ndarray]: ...


class SequenceCheck(Protocol):
    """How the preflight checks the sequence again from where the arm stands
    (:func:`seqrun.sequence.checks.check_from_arm`): given to the executor by whoever
    makes it, so the loop needs nothing of the sequence layer but the steps it runs."""

    def __call__(self, loaded: Any, arm: ArmDescription, start_deg: dict[str, float], *,
                 first_step: int, started: bool, speed: float,
                 module_limits: Mapping[str, tuple[float, float]]) -> Findings: ...

#: MinPos/MaxPos the drives hold count as the arm file's within this (the float32 a drive
#: stores, 1e-5 rad).
LIMITS_MATCH_DEG = math.degrees(1e-5)


def preflight(run: Run, check: SequenceCheck, loaded, first_step: int = 1) -> Findings:
    """Read the arm and ``check`` ``loaded`` (from ``first_step``) from the measured state.
    Returns what the check found; only reads reach the bus."""
    arm = run.arm
    m, states, module_limits, written = _measure(run)
    run.limits_in_force.read_back(module_limits)
    ready = all(f.ready for f in states.values())
    run.latched.record(states)
    started = ready and written
    start_deg = {j.name: float(v) for j, v in zip(arm.joints, m.user_deg)}
    result = check(loaded, arm, start_deg, first_step=first_step, started=started,
                   speed=run.speed, module_limits=module_limits)
    run.validated_targets = dict(result.targets_deg)
    run.planned_paths = dict(getattr(result, "paths", {}))
    run.hazards = dict(getattr(result, "hazards", {}))
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


def _measure(run: Run) -> tuple[Any, dict, dict[str, tuple[float, float]], bool]:
    """One reading of the arm, every module's full state, MaxVel/MaxAcc per joint as the
    drives hold them and whether they hold the arm file's position limits: only reads
    reach the bus."""
    m = run.read_arm()
    states = run.read_state_words()
    run.beat()
    stored = run.driver.read_limits()
    joints = run.arm.joints
    written = all(abs(held.min_deg - j.limits_deg[0]) < LIMITS_MATCH_DEG
                  and abs(held.max_deg - j.limits_deg[1]) < LIMITS_MATCH_DEG
                  for j, held in zip(joints, stored))
    module_limits = {j.name: (held.max_velocity_deg_s, held.max_acceleration_deg_s2)
                     for j, held in zip(joints, stored)}
    return m, states, module_limits, written


def recheck(run: Run, check: SequenceCheck, loaded: Any) -> Findings:
    """``loaded`` (the steps a run goes on with after a recoverable failure: a block's
    rescue, its always, what follows) checked from where the arm stands now, as the
    preflight checks the whole sequence: nothing moves if it finds an error. The targets
    and paths it validated replace those of the same steps."""
    m, states, module_limits, written = _measure(run)
    start_deg = {j.name: float(v) for j, v in zip(run.arm.joints, m.user_deg)}
    started = written and all(f.ready for f in states.values())
    result = check(loaded, run.arm, start_deg, first_step=1, started=started,
                   speed=run.speed, module_limits=module_limits)
    run.validated_targets.update(result.targets_deg)
    if run.planned_paths is not None:
        run.planned_paths.update(getattr(result, "paths", {}))
    run.hazards.update(getattr(result, "hazards", {}))
    return result
