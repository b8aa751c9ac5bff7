"""Jog: one joint at a commanded speed for as long as the operator keeps renewing it (deadman).

A jog is an ordinary executor move (``Executor.move``: planned with ruckig, streamed with the
same per-cycle checks of state flags, following error and workspace guards, Halt on any fault)
towards the farthest point of the joint's range that keeps a margin to its limit and to every
workspace guard. The deadman is checked on the control loop's own thread, once per cycle
(an executor idle hook): when no renewal came within ``deadman_s`` it posts an abort, and the
executor brings the joint to rest with its controlled stop (ruckig to zero velocity) and
holds. Nothing restarts the motion: a new jog is a new command.

In velocity mode (``mode="velocity"``, the thesis GUI's FVEL jog) the same plan is streamed
as FVEL setpoints (the driver's velocity law): the driver arms the modules' watchdog before
the first FVEL, so a silent host stops the joint within the watchdog timeout, and every cycle
checks that the joint's position plus its stopping distance stays inside its limits (less
half the margin); a clean end disarms the watchdog again.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from typing import Callable

import numpy as np

from seqrun.arm import kinematics
from seqrun.arm.tools import ToolVolumes
from seqrun.errors import Refused

#: Margin (deg) a jog keeps to the joint's limits: it is refused closer than this.
LIMIT_MARGIN_DEG = 1.0
#: Margin (mm) a jog keeps above every workspace guard's plane.
GUARD_MARGIN_MM = 10.0
#: Step (deg) of the search along the joint for the guard-limited end of the jog.
SEARCH_STEP_DEG = 0.5
#: How a jog is streamed: position setpoints (FRAMP, the run's law) or velocities (FVEL).
JOG_MODES = ("position", "velocity")


@dataclass(frozen=True)
class JogPlan:
    joint: str
    index: int
    direction: int
    start_deg: float
    end_deg: float
    velocity_deg_s: float
    why_end: str
    mode: str = "position"


def plan_jog(arm, joint: str, speed_scale: float, joints_deg: np.ndarray,
             jog_velocity_deg_s: float, mode: str = "position") -> JogPlan:
    """Where a jog of ``joint`` from ``joints_deg`` (user degrees) may go; raises
    :class:`Refused` (one line) for an unknown or locked joint, a scale outside [-1, 1] or 0,
    a joint at its limit (within :data:`LIMIT_MARGIN_DEG`, moving towards it) or an arm
    outside its workspace guards, or one that would leave them at once."""
    if mode not in JOG_MODES:
        raise Refused(f"jog: mode {mode!r} must be one of {', '.join(JOG_MODES)}")
    if joint not in arm.joint_names:
        raise Refused(f"jog: unknown joint '{joint}' (joints: {', '.join(arm.joint_names)})")
    index = arm.joint_names.index(joint)
    spec = arm.joints[index]
    if spec.locked is not None:
        raise Refused(f"jog: {joint} is locked at {spec.locked:g}° in the arm file")
    if not isinstance(speed_scale, (int, float)) or not math.isfinite(speed_scale):
        raise Refused(f"jog: speed scale {speed_scale!r} is not a finite number")
    if not -1.0 <= speed_scale <= 1.0 or speed_scale == 0:
        raise Refused(f"jog: speed scale {speed_scale:g} must lie in [-1, 1] and not be 0")
    direction = 1 if speed_scale > 0 else -1
    lo, hi = spec.limits_deg
    start = float(joints_deg[index])
    limit = (hi - LIMIT_MARGIN_DEG) if direction > 0 else (lo + LIMIT_MARGIN_DEG)
    if (limit - start) * direction <= 0:
        raise Refused(f"jog: {joint} at {start:.2f}° is at its "
                      f"{'upper' if direction > 0 else 'lower'} limit "
                      f"({hi if direction > 0 else lo:g}°, margin {LIMIT_MARGIN_DEG:g}°)")
    chain = kinematics.Chain.from_arm(arm)
    tools = ToolVolumes(arm)
    q = np.radians(np.asarray(joints_deg, dtype=float))
    low = _lowest_guard(arm, chain, q, tools)
    if low is not None and low[1] < low[2]:
        raise Refused(f"jog: the arm is outside its workspace guard '{low[0]}' "
                      f"({low[3]} at z = {low[1]:.1f} mm, below {low[2]:.1f} mm); move it "
                      "back with a validated move")
    end, why = limit, "joint limit"
    n = int(abs(limit - start) / SEARCH_STEP_DEG) + 1
    for k in range(1, n + 1):
        x = start + direction * min(k * SEARCH_STEP_DEG, abs(limit - start))
        q_k = q.copy()
        q_k[index] = math.radians(x)
        low = _lowest_guard(arm, chain, q_k, tools)
        if low is not None and low[1] < low[2] + GUARD_MARGIN_MM:
            end = start + direction * (k - 1) * SEARCH_STEP_DEG
            why = f"workspace guard '{low[0]}'"
            break
    if abs(end - start) < SEARCH_STEP_DEG / 2:
        raise Refused(f"jog: {joint} {'+' if direction > 0 else '-'} would bring the arm "
                      f"within {GUARD_MARGIN_MM:g} mm of its {why}")
    return JogPlan(joint, index, direction, start, end,
                   jog_velocity_deg_s * abs(speed_scale), why, mode)


def _lowest_guard(arm, chain, q_rad, tools: ToolVolumes | None = None
                  ) -> tuple[str, float, float, str] | None:
    """(guard, z of its lowest point, min_z, point) for the guard closest to being broken;
    a guard that watches the end-effector watches the tools' volumes too (as a run does)."""
    tools = tools if tools is not None else ToolVolumes(arm)
    heights, tool_z = kinematics.heights_of_points(
        chain, q_rad, None if tools.empty else tools.points_mm)
    found: dict[str, float] = dict(heights.items())
    tool_label = ""
    if not tools.empty:
        found["tool"], tool_label = tools.lowest_z(tool_z)
    worst = None
    for guard in arm.workspace.guards:
        watched = list(guard.points)
        if "end_effector" in watched and tool_label:
            watched.append("tool")
        for name in watched:
            z = found[name]
            if worst is None or z - guard.min_z_mm < worst[1] - worst[2]:
                worst = (guard.name, z, guard.min_z_mm, tool_label if name == "tool" else name)
    return worst


class Deadman:
    """Renewed by the operator's face (any thread); checked by the loop every cycle and, in
    real time, by a supervisor thread of its own (a loop that is late has no idle time to
    run hooks in). Posts at most one abort, so a release after expiry is never a second
    abort (which the executor would take for a Halt)."""

    #: How often the supervisor thread looks (real seconds).
    SUPERVISE_S = 0.02

    def __init__(self, clock, deadman_s: float) -> None:
        self.clock = clock
        self.deadman_s = deadman_s
        self._lock = threading.Lock()
        self._renewed = clock.now()
        self._released: str | None = None
        self._abort: Callable[[str], None] | None = None
        self.expired = False
        self.reason = ""
        self._done = threading.Event()

    def renew(self) -> None:
        with self._lock:
            self._renewed = self.clock.now()

    def overdue(self) -> bool:
        with self._lock:
            return self.clock.now() - self._renewed > self.deadman_s

    def release(self, reason: str = "jog stopped") -> None:
        """End the jog now (controlled stop), from any thread."""
        with self._lock:
            self._released = self._released or reason
        self.check()

    def check(self) -> None:
        """Post the one abort when released or overdue (any thread, idempotent)."""
        with self._lock:
            if self.expired or self._abort is None:
                return
            if self._released is not None:
                reason = self._released
            elif self.clock.now() - self._renewed > self.deadman_s:
                reason = f"jog released: not renewed within {self.deadman_s * 1000:.0f} ms"
            else:
                return
            self.expired, self.reason, abort = True, reason, self._abort
        abort(reason)

    def arm(self, abort: Callable[[str], None]) -> Callable[[float], None]:
        """Start watching for ``abort`` (the executor's): returns the idle hook; in real
        time also starts the supervisor thread. :meth:`disarm` when the jog has ended."""
        with self._lock:
            self._abort = abort
        if not getattr(self.clock, "is_virtual", False):
            threading.Thread(target=self._supervise, daemon=True,
                             name="seqrun-jog-deadman").start()
        return lambda slack: self.check()

    def disarm(self) -> None:
        self._done.set()

    def _supervise(self) -> None:
        while not self._done.wait(self.SUPERVISE_S):
            self.check()


def _follow_in_velocity_mode(executor, plan: JogPlan, target: np.ndarray, limits,
                             start) -> None:
    """The jog's plan streamed as FVEL (driver's velocity law), with the limits and
    stopping-distance check of every cycle; a clean end disarms the watchdog the
    driver armed for it."""
    from seqrun.arm.planner import plan_move
    from seqrun.arm.velocity import stop_position
    from seqrun.errors import RunAborted
    from seqrun.results import OperatorAbort

    arm = executor.arm
    i = plan.index
    lo, hi = arm.joints[i].limits_deg
    lo, hi = lo + LIMIT_MARGIN_DEG / 2, hi - LIMIT_MARGIN_DEG / 2
    braking = float(np.degrees(limits.acceleration[i]))
    last = [start]

    def inside_limits(m) -> None:
        before, last[0] = last[0], m
        dt = m.t - before.t
        velocity = (m.user_deg[i] - before.user_deg[i]) / dt if dt > 0 else 0.0
        stop = stop_position(float(m.user_deg[i]), float(velocity), braking)
        if not lo <= stop <= hi:
            raise RunAborted("envelope", f"jog {plan.joint}: at {m.user_deg[i]:.2f}° moving "
                             f"{velocity:+.2f} deg/s it would stop at {stop:.2f}°, beyond "
                             f"{lo:g}…{hi:g}°", module=arm.joints[i].module)

    path = plan_move(np.radians(start.user_deg), np.radians(target), limits, [i])
    try:
        executor.follow(path, tolerance_deg=arm.control.position_tolerance_deg,
                        timeout_s=None, path_check=inside_limits, command_mode="velocity",
                        start=start)
    except OperatorAbort:  # released: a controlled stop, the joint holds
        executor.driver.disable_watchdog()
        raise
    executor.driver.disable_watchdog()


def run_jog(executor, plan: JogPlan, deadman: Deadman) -> tuple[str, int, str]:
    """Stream the jog with ``executor`` (owned by the caller); returns (status, exit code,
    message). Any fault -> Halt (the executor's emergency Halt), exit 3."""
    from seqrun.defaults import EXIT_FAULT, EXIT_OK
    from seqrun.results import OperatorAbort, fault_cause, halt_fields
    from seqrun.arm.planner import Limits

    arm = executor.arm
    hook = deadman.arm(executor.abort)
    executor.idle_hooks.append(hook)
    try:
        m = executor.read_arm()
        executor.check_states(m)
        if plan.mode == "velocity":
            # The watchdog the driver arms for FVEL is fed between cycles only while this
            # loop shows signs of life (as in a run).
            executor.beat()
            executor.driver.enable_watchdog(executor.loop_alive)
        target = m.user_deg.copy()
        target[plan.index] = plan.end_deg
        velocity, acceleration = executor.limits_in_force.maxima()
        limits = Limits.from_arm(arm, velocity_deg_s={plan.joint: plan.velocity_deg_s},
                                 max_velocity_deg_s=velocity,
                                 max_acceleration_deg_s2=acceleration)
        executor.emit("jog_started", joint=plan.joint, direction=plan.direction,
                      velocity_deg_s=round(plan.velocity_deg_s, 3),
                      end_deg=round(plan.end_deg, 3), end_reason=plan.why_end, mode=plan.mode)
        try:
            if plan.mode == "velocity":
                _follow_in_velocity_mode(executor, plan, target, limits, m)
            else:
                executor.move(target, [plan.index], limits,
                              tolerance_deg=arm.control.position_tolerance_deg,
                              timeout_s=None, start=m)
            message = f"jog {plan.joint}: stopped at the end of its range ({plan.why_end})"
        except OperatorAbort:  # the deadman or jog_stop: the arm holds after the stop
            message = f"jog {plan.joint}: {deadman.reason or 'stopped'}; controlled stop"
        executor.emit("jog_stopped", joint=plan.joint, reason=message,
                      joints_deg=[round(float(x), 3) for x in executor.last.user_deg]
                      if executor.last is not None else None)
        return "passed", EXIT_OK, message
    except Exception as exc:  # noqa: BLE001 - every failure, even a bug, halts
        executor.emergency_halt()
        cause, module = fault_cause(exc)
        message = executor.describe_error(exc)
        if cause == "operator_halt":
            return "aborted", 130, f"jog {plan.joint}: {message}"
        executor.emit("fault", cause=cause, module=module, message=message, step=None,
                      **halt_fields(executor.halt_result))
        return "failed", EXIT_FAULT, message
    finally:
        deadman.disarm()
        if hook in executor.idle_hooks:
            executor.idle_hooks.remove(hook)
