"""Before the first step: read the arm and check the sequence again from where it stands.

The preflight reads every joint and its full state and the limits the drives hold
(MinPos/MaxPos/MaxVel/MaxAcc stay stored across runs), then validates the sequence (from
``--from N``) from the measured state with those limits: nothing moves if that fails. A
fault the modules had latched before the run is told (:mod:`.latched`).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from seqrun.drivers.telemetry import joint_flags
from seqrun.events import make_event
from seqrun.execution.run import rounded

if TYPE_CHECKING:
    from seqrun.execution.run import Run

#: MinPos/MaxPos the drives hold count as the arm file's within this (the float32 a drive
#: stores, 1e-5 rad).
LIMITS_MATCH_DEG = math.degrees(1e-5)


def preflight(run: Run, loaded, first_step: int = 1):
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
