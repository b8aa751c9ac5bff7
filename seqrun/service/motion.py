"""The session's own motions and commands: reset, home, arm-up, moves to a pose or to joint
targets, the session's move velocities, and the jog.

Every motion goes through the sequence machinery: a move is a one-step sequence written to
a private folder, loaded by the same loader, validated from the measured joints by the same
validator and run by the same executor (the same per-cycle checks, the same Halt on any
fault). Bad input and the wrong state are refused (:class:`~seqrun.errors.Refused`, one
line) before anything is sent. Part of the arm session (:mod:`seqrun.service.session`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from seqrun.errors import Refused
from seqrun.service.activities import Activity, ActivityResult, activity_result

#: A jog that is not renewed within this time ends with a controlled stop (deadman).
JOG_DEADMAN_S = 0.2

#: Share of each joint's maximum velocity the session's moves use until told otherwise.
DEFAULT_MOVE_SHARE = 0.25


def finite(value: Any, what: str) -> float:
    """``value`` as a finite float, or Refused naming ``what``; a boolean or a text is not
    a number (``True`` is not 1 and ``"12"`` not 12: every face passes typed values on)."""
    import numbers

    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise Refused(f"{what}: {value!r} is not a number")
    x = float(value)
    if not math.isfinite(x):
        raise Refused(f"{what}: {value!r} is not a finite number")
    return x


class Motion:
    """Moves, commands and the jog of one session (its ``arm``, ``project``,
    ``activities``, ``telemetry``, ``clock``)."""

    def __init__(self, session: Any, *, jog_deadman_s: float = JOG_DEADMAN_S) -> None:
        self._session = session
        self.jog_deadman_s = jog_deadman_s
        self._velocities = {j.name: round(j.max_velocity_deg_s * DEFAULT_MOVE_SHARE, 3)
                            for j in session.arm.joints if j.locked is None}
        self._tmp: Path | None = None

    # ------------------------------------------------------------------ one-step sequences
    def one_off(self, name: str, steps: list[str]):
        """A sequence built in memory (a file in a private folder, loaded by the same
        loader): the console's moves and commands are sequences like any other."""
        from seqrun.errors import SequenceInvalid, UserInputError
        from seqrun.sequence.loader import load_sequence

        if self._tmp is None:
            import tempfile

            self._tmp = Path(tempfile.mkdtemp(prefix="seqrun-session-"))
        path = self._tmp / f"{name}.yaml"
        path.write_text(f"name: {name}\ndescription: seqrun session command\nsteps:\n"
                        + "".join(f"  - {s}\n" for s in steps), encoding="utf-8")
        project = self._session.project
        root = project.root if project is not None else None
        try:
            return load_sequence(path, project_root=root)
        except SequenceInvalid as exc:
            raise Refused(exc.errors[0].message) from None
        except UserInputError as exc:
            raise Refused(str(exc)) from None

    def _blocking_steps(self, kind: str, steps: list[str]) -> ActivityResult:
        s = self._session
        loaded = self.one_off(kind, steps)
        activity = s.activities.begin(kind)

        def work() -> ActivityResult:
            executor = s.activities.new_executor(loaded, confirm_clear_latched=lambda q: True)
            result = executor.run(loaded)
            if result.exit_code == 0 and kind != "home":
                s.telemetry.mark_cleared()
            s.telemetry.poll_once()
            return activity_result(kind, result)

        s.activities.launch(activity, work, background=False)
        return activity.wait()

    # ------------------------------------------------------------------ blocking commands
    def reset(self) -> ActivityResult:
        """Reset every module (clears faults and Halt), confirmed by reading back."""
        return self._blocking_steps("reset", ["reset: {label: Reset (session)}"])

    def home(self) -> ActivityResult:
        """Home every module (reset of the power-on error state, then Home; no motion on
        the LWA 3), confirmed (HOME_OK read back). Refused while halted: a Reset after a
        STOP is the operator's explicit decision."""
        self.check_movable("home", homed=False)
        return self._blocking_steps("home", ["reset: {label: Reset (home)}",
                                             "home: {label: Home (session)}"])

    def arm_up(self) -> ActivityResult:
        """"ARM" of the thesis console: reset, then write the arm file's limits."""
        return self._blocking_steps("arm_up", ["reset: {label: Reset (arm up)}",
                                               "set_limits: {label: Write the limits (arm up)}"])

    # ------------------------------------------------------------------ velocities
    def set_move_velocities(self, velocities_deg_s: Mapping[str, float]) -> dict[str, float]:
        """Per-joint velocity (deg/s) of the session's moves (the thesis ALLVEL); joints not
        named keep theirs. Returns the velocities in force. Refused: unknown joint, NaN, not
        positive, above the joint's limit."""
        if not isinstance(velocities_deg_s, Mapping):
            raise Refused("move velocities: give a mapping joint -> deg/s")
        new = {}
        for name, value in velocities_deg_s.items():
            joint = self.movable_joint(name, "move velocity")
            v = finite(value, f"move velocity of {name}")
            if v <= 0:
                raise Refused(f"move velocity of {name}: {v:g} deg/s must be positive")
            if v > joint.max_velocity_deg_s:
                raise Refused(f"move velocity of {name}: {v:g} deg/s is above its limit "
                              f"{joint.max_velocity_deg_s:g} deg/s")
            new[name] = v
        self._velocities.update(new)
        return dict(self._velocities)

    def move_velocities(self) -> dict[str, float]:
        return dict(self._velocities)

    # ------------------------------------------------------------------ refusals
    def movable_joint(self, name: Any, what: str):
        arm = self._session.arm
        if not isinstance(name, str) or name not in arm.joint_names:
            raise Refused(f"{what}: unknown joint {name!r} (joints: "
                          f"{', '.join(arm.joint_names)})")
        joint = arm.joints[arm.joint_names.index(name)]
        if joint.locked is not None:
            raise Refused(f"{what}: {name} is locked at {joint.locked:g}° in the arm file")
        return joint

    def check_movable(self, what: str, *, homed: bool = True) -> None:
        """Refused while halted or faulted, not homed (``homed``), or before anything was
        measured."""
        telemetry = self._session.telemetry
        now = telemetry.condition()
        if now.halted is not None or any("HALTED" in f for f in now.flags.values()):
            raise Refused(f"{what}: the arm is halted ({now.halted or 'HALTED'}); "
                          "reset it first")
        if not homed:
            return
        bad = [f"{n}: {'|'.join(f)}" for n, f in now.flags.items() if telemetry.flags_fault(f)]
        if now.fault or bad:
            raise Refused(f"{what}: module fault ({'; '.join(bad) or 'NOT_OK'}); reset it first")
        if not now.measured:
            raise Refused(f"{what}: the arm has not been read yet")
        if now.homed is False:
            raise Refused(f"{what}: the modules are not homed; Arm and Home first")

    @staticmethod
    def scale(value: Any) -> float:
        v = finite(value, "velocity scale")
        if not 0 < v <= 1:
            raise Refused(f"velocity scale {v:g} must lie in (0, 1]")
        return v

    # ------------------------------------------------------------------ moves
    def _validated_move(self, kind: str, step: str, what: str):
        """Load and validate a one-step move from the measured joints (Refused on errors)."""
        from seqrun.sequence.validation import validate_sequence

        self.check_movable(what)
        loaded = self.one_off(kind, [step])
        start = self._session.telemetry.joints_deg()
        check = validate_sequence(loaded, self._session.arm, start, started=True)
        if check.errors:
            raise Refused(f"{what}: {self._own_words(check.errors[0])}")
        if self._session.separation is not None:  # against the other arms (and their plans)
            self._session.separation.refuse_paths(what, check.paths)
        return loaded

    def validated_step(self, kind: str, step: str, what: str):
        """A one-step sequence of ``step`` (YAML text), validated from the measured joints
        (Refused on errors): what a face's command runs (the gripper's too)."""
        return self._validated_move(kind, step, what)

    def start_steps(self, kind: str, loaded, detail: dict,
                    by: str | None = None) -> Activity:
        """Run a validated one-off sequence as the session's activity (non-blocking)."""
        return self._start_move(kind, loaded, detail, by)

    def _own_words(self, error) -> str:
        """A finding about a session command in the operator's terms: where it is when that
        is a file of theirs (a pose file), never the session's private one-step file."""
        import re

        private = str(self._tmp or "\0")
        message = re.sub(r"\s*\(used at [^()]*" + re.escape(private) + r"[^()]*\)", "",
                         error.message)
        if str(error.file).startswith(private):
            return message
        return f"{error.file}:{error.line}:{error.column}: {message}"

    def _start_move(self, kind: str, loaded, detail: dict, by: str | None = None) -> Activity:
        s = self._session
        activity = s.activities.begin(kind, detail, by)

        def work() -> ActivityResult:
            executor = s.activities.new_executor(loaded)
            result = executor.run(loaded)
            s.telemetry.poll_once()
            return activity_result(kind, result)

        return s.activities.launch(activity, work, background=True)

    def move_to_pose(self, name: str, *, velocity_scale: float | None = None,
                     by: str | None = None) -> Activity:
        """Move to a named pose (a pose file), as a one-step sequence: validated, executed
        by the executor. Non-blocking."""
        import json

        if not isinstance(name, str) or not name:
            raise Refused(f"move to pose: {name!r} is not a pose name")
        params: dict[str, Any] = {"pose": name, "label": f"Move to {name} (session)"}
        if velocity_scale is not None:
            params["velocity_scale"] = self.scale(velocity_scale)
        else:
            params["velocity_deg_s"] = self.move_velocities()
        loaded = self._validated_move("move", f"move: {json.dumps(params)}",
                                      f"move to {name}")
        return self._start_move("move", loaded, {"pose": name}, by)

    def move_to_joints(self, joints_deg: Mapping[str, float], *,
                       velocity_scale: float | None = None, by: str | None = None) -> Activity:
        """Move the named joints to user-degree targets (others stay). Non-blocking."""
        import json

        if not isinstance(joints_deg, Mapping) or not joints_deg:
            raise Refused("move: give at least one joint target (joint -> degrees)")
        targets = {}
        for name, value in joints_deg.items():
            joint = self.movable_joint(name, "move")
            v = finite(value, f"move: {name}")
            lo, hi = joint.limits_deg
            if not lo <= v <= hi:
                raise Refused(f"move: {name} target {v:g}° is outside its limits "
                              f"[{lo:g}, {hi:g}]°")
            targets[name] = v
        params: dict[str, Any] = {"joints": targets, "label": "Move joints (session)"}
        if velocity_scale is not None:
            params["velocity_scale"] = self.scale(velocity_scale)
        params["velocity_deg_s"] = {n: v for n, v in self.move_velocities().items()
                                    if n in targets}
        loaded = self._validated_move("move", f"move: {json.dumps(params)}", "move")
        return self._start_move("move", loaded, {"joints": targets}, by)

    # ------------------------------------------------------------------ jog
    def jog(self, joint: str, speed_scale: float, *, by: str | None = None,
            mode: str = "position") -> Activity:
        """Jog one joint at ``speed_scale`` (-1..1) of its move velocity. Call again at
        least every :data:`JOG_DEADMAN_S` (same joint and direction: renews; the speed
        stays the first call's) or the jog ends with a controlled stop. Refused near a
        limit (moving towards it) or outside the workspace guards, like a move; another
        joint or the other direction while jogging is refused (release first). ``mode``:
        "position" (FRAMP setpoints) or "velocity" (FVEL, the thesis GUI's jog, with the
        modules' watchdog armed while it moves)."""
        import numpy as np

        from seqrun.service.jog import Deadman, plan_jog, run_jog

        s = self._session
        activities = s.activities
        current, deadman, plan = activities.current, activities.deadman, activities.jog_plan
        if current is not None and current.kind == "jog" and deadman is not None:
            if (plan is not None and plan.joint == joint
                    and isinstance(speed_scale, (int, float))
                    and not isinstance(speed_scale, bool)
                    and speed_scale * plan.direction > 0 and plan.mode == mode
                    and not deadman.expired):
                deadman.renew()  # the speed stays the jog's first
                return current
            raise Refused("jog: another jog is under way (release it first)")
        self.check_movable("jog")
        speed_scale = finite(speed_scale, "jog: speed scale")
        joints = np.array(s.telemetry.condition().joints, dtype=float)
        velocity = self._velocities.get(joint, 0.0)
        plan = plan_jog(s.arm, joint, float(speed_scale), joints, velocity, mode)
        if s.separation is not None:  # its next stretch against the other arms
            s.separation.refuse_jog("jog", joints, plan.index, plan.end_deg,
                                    plan.velocity_deg_s, self.jog_deadman_s)
        deadman = Deadman(s.clock, self.jog_deadman_s)
        activity = activities.begin("jog", {"joint": joint, "speed_scale": speed_scale,
                                            "mode": mode}, by)
        activities.deadman, activities.jog_plan = deadman, plan

        def work() -> ActivityResult:
            executor = activities.new_executor()
            status, code, message = run_jog(executor, plan, deadman)
            s.telemetry.poll_once()  # at rest: the modules' own velocities, not the estimate
            return ActivityResult("jog", status, code, message)

        return activities.launch(activity, work, background=True)

    def jog_stop(self) -> ActivityResult | None:
        """End the jog with a controlled stop (waits for it); None if no jog ran."""
        activities = self._session.activities
        activity, deadman = activities.current, activities.deadman
        if activity is None or activity.kind != "jog":
            return None
        if deadman is not None:
            deadman.release("jog stopped")
        return activity.wait(timeout=30.0)
