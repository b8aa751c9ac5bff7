"""Streaming a plan to the arm, cycle by cycle, and watching it while it waits.

Each control cycle (``control.cycle_hz``) sends the plan's setpoints through the driver and
gets a reading of every joint back; the reading is checked (state flags, guards, link
volumes, the step's path check) and held against the plan (following error). An abort or a
pause ends the stream with a controlled stop (ruckig to zero velocity, streamed), then
hold; a Halt request, a refused motion or any fault raises, and the executor halts the arm.
Waits and checkpoints monitor every cycle without commanding anything.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from seqrun.arm.planner import Limits, MovePlan, plan_move, plan_stop
from seqrun.arm.tracking import MoveTracking, velocity_window
from seqrun.arm.trajectory_tolerances import (GOAL_TOLERANCE_VIOLATED, PATH_TOLERANCE_VIOLATED,
                                              TrajectoryTolerances)
from seqrun.drivers.base import MotionRefused
from seqrun.errors import RunAborted
from seqrun.execution.monitors import MonitorTripped
from seqrun.execution.run import rounded
from seqrun.results import OperatorAbort

if TYPE_CHECKING:
    from seqrun.execution.run import Measurement, Run


def _round(x: float | None, nd: int = 4) -> float | None:
    return None if x is None else round(float(x), nd)


def plan_time_of(plan: MovePlan, measured_deg: np.ndarray, moving: list[int],
                 earliest: float, latest: float) -> float:
    """The plan time in [earliest, latest] at which the plan stands where the arm is, read on
    the joint with the longest way (a point-to-point plan moves each joint one way)."""
    if not moving:
        return latest
    start, target = np.degrees(plan.start), np.degrees(plan.target)
    j = max(moving, key=lambda i: abs(target[i] - start[i]))
    direction = math.copysign(1.0, target[j] - start[j])

    def ahead_of_arm(tau: float) -> bool:
        return (math.degrees(plan.at(tau)[0][j]) - measured_deg[j]) * direction > 0

    if ahead_of_arm(earliest):
        return earliest
    if not ahead_of_arm(latest):
        return latest
    lo, hi = earliest, latest
    while hi - lo > 1e-3:
        mid = (lo + hi) / 2
        lo, hi = (lo, mid) if ahead_of_arm(mid) else (mid, hi)
    return lo


class Streaming:
    """The moves and waits of one run (the executor it streams for: its driver, clock,
    checks, stop requests and events)."""

    def __init__(self, run: Run) -> None:
        self.run = run
        #: The figures of the move under way (seqrun/arm/tracking.py).
        self.tracking: MoveTracking | None = None
        #: The limits the move under way was planned with.
        self.move_limits = run.limits
        #: Extra check of every streamed cycle (a straight-line move's deviation).
        self.path_check: Callable[[Measurement], None] | None = None
        #: Host stalls (s) the plans were held for, this run (``host_stall`` events).
        self.stalls: list[float] = []

    # ------------------------------------------------------------------ moves
    def move(self, target_deg: np.ndarray, active: list[int], limits: Limits, *,
             tolerance_deg: float, timeout_s: float | None,
             start: Measurement | None = None) -> dict[str, Any]:
        run = self.run
        m = start if start is not None else run.read_arm()
        run.check_states(m)
        self.move_limits = limits
        start_deg = m.user_deg.copy()
        run.motion_start_deg = start_deg.copy()  # for relative checkpoints
        moving = [i for i in active if abs(target_deg[i] - start_deg[i]) > 1e-9]
        plan = plan_move(np.radians(start_deg), np.radians(target_deg), limits, moving)
        run.commanded_deg = np.where(np.isin(np.arange(len(target_deg)), moving),
                                     target_deg, start_deg)
        velocity_limit = rounded(np.degrees(limits.velocity))
        run.emit("move_planned", duration_s=_round(plan.duration),
                 start_deg=rounded(start_deg), target_deg=rounded(target_deg),
                 joints=[run.arm.joints[i].name for i in moving],
                 velocity_limit_deg_s=velocity_limit)
        if run.current_step is not None:
            run.current_step.planned_duration_s = plan.duration
        if timeout_s is not None and plan.duration > timeout_s:
            raise RunAborted("timeout", f"the move is planned to take {plan.duration:.3g} s, "
                             f"longer than its timeout_s {timeout_s:g} s; nothing was moved")
        self.tracking = MoveTracking(velocity_window(run.cycle))
        t_move = run.clock.now()
        if moving:
            run.beat()
            run.driver.start_motion(moving, limits)
            # A step's timeout covers the whole move; the default allows the plan plus
            # the arm's settle time.
            deadline = (timeout_s if timeout_s is not None
                        else plan.duration + run.arm.control.settle_timeout_s)
            try:
                self.stream(plan, moving, tolerance_deg, deadline, stop_on_abort=True)
            finally:
                run.driver.end_motion()
        elapsed = run.clock.now() - t_move
        return {"planned_duration_s": plan.duration, "executed_duration_s": elapsed,
                "duration_ratio": _round(elapsed / plan.duration) if plan.duration > 0 else None,
                "peak_velocity_deg_s": rounded(np.degrees(plan.peak_velocity())),
                "peak_measured_velocity_deg_s": [0.0] * len(target_deg),
                "velocity_limit_deg_s": velocity_limit,
                **self.tracking_figures(target_deg)}

    def tracking_figures(self, target_deg=None) -> dict[str, Any]:
        """The current move's tracking figures (seqrun/arm/tracking.py) up to now."""
        if self.tracking is None:
            return {}
        target = self.run.commanded_deg if target_deg is None else target_deg
        return self.tracking.figures(target)

    def follow(self, plan, *, tolerance_deg: float | np.ndarray, timeout_s: float | None,
               path_check: Callable[[Measurement], None] | None = None,
               command_mode: str | None = None,
               start: Measurement | None = None,
               tolerances: TrajectoryTolerances | None = None) -> dict[str, Any]:
        """Stream ``plan``; ``tolerances`` (a trajectory's, JTC's): per-joint path
        tolerances checked every cycle of the plan, per-joint goal tolerances (over
        ``tolerance_deg``) and the time after the plan's end they must be met by."""
        run = self.run
        names = run.arm.joint_names
        path_tolerance = None
        goal = False
        if tolerances is not None and not tolerances.empty:
            path_tolerance = tolerances.path_array(names) if tolerances.path_deg else None
            tolerance_deg = tolerances.goal_array(names, float(np.max(tolerance_deg)))
            goal = True
            if tolerances.goal_time_s is not None:
                timeout_s = plan.duration + tolerances.goal_time_s
        m = start if start is not None else run.read_arm()
        run.check_states(m)
        run.motion_start_deg = m.user_deg.copy()  # for relative checkpoints
        moving = list(plan.active)
        run.commanded_deg = np.degrees(plan.target)
        run.emit("move_planned", duration_s=_round(plan.duration),
                 start_deg=rounded(m.user_deg), target_deg=rounded(np.degrees(plan.target)),
                 joints=[run.arm.joints[i].name for i in moving], sampled=True)
        if run.current_step is not None:
            run.current_step.planned_duration_s = plan.duration
        self.tracking = MoveTracking(velocity_window(run.cycle))
        t_move = run.clock.now()
        if moving:
            deadline = (timeout_s if timeout_s is not None
                        else plan.duration + run.arm.control.settle_timeout_s)
            self.path_check = path_check
            try:
                run.beat()
                run.driver.start_motion(moving, run.limits, command_mode=command_mode)
                self.stream(plan, moving, tolerance_deg, deadline, stop_on_abort=True,
                            path_tolerance_deg=path_tolerance, goal=goal)
            finally:
                self.path_check = None
                run.driver.end_motion()
        elapsed = run.clock.now() - t_move
        return {"planned_duration_s": plan.duration, "executed_duration_s": elapsed,
                "duration_ratio": _round(elapsed / plan.duration) if plan.duration > 0 else None,
                "peak_velocity_deg_s": rounded(np.degrees(plan.peak_velocity())),
                "peak_measured_velocity_deg_s": [0.0] * run.arm.dof,
                **self.tracking_figures(np.degrees(plan.target))}

    # ------------------------------------------------------------------ the stream
    def cycle(self, plan: MovePlan, t: float, moving: list[int],
              measured_deg: np.ndarray) -> Measurement:
        """One control cycle through the driver: ``plan``'s setpoints at plan time ``t``
        for ``moving``, and a reading of every joint.

        The driver looks at every answer as it arrives: the first that refuses motion
        ends the cycle at once, and the arm is halted before anything else; then the
        module's full state names the cause.
        """
        run = self.run
        run.beat()
        try:
            reading = run.driver.cycle(plan, t, moving, measured_deg)
        except MotionRefused as refused:
            run.emergency_halt()
            raise run.checks.fault_after_halt(refused.module, refused.state) from None
        try:
            return run.take_reading(reading)
        except MonitorTripped as tripped:
            if tripped.controlled:  # a monitor's ``stop``: brake smoothly, then the fault
                self.controlled_stop(plan, t, moving, from_deg=reading.positions_deg)
            raise

    def stream(self, plan: MovePlan, moving: list[int], tolerance_deg: float | np.ndarray,
               deadline: float, *, stop_on_abort: bool,
               path_tolerance_deg: np.ndarray | None = None, goal: bool = False) -> None:
        """Stream ``plan`` cycle by cycle until every moving joint is in tolerance
        (``tolerance_deg``: one for all joints or one per joint). ``path_tolerance_deg``:
        per joint, the following error that stops the motion while the plan runs (inf:
        none); ``goal``: not in tolerance by ``deadline`` is GOAL_TOLERANCE_VIOLATED."""
        run = self.run
        stops = run.stops
        t_start = run.clock.now()
        bound = run.arm.control.max_following_error_deg
        measured = run.last.user_deg if run.last is not None else np.degrees(plan.start)
        k = 0
        last_t: float | None = None
        waited = False
        while True:
            t_cycle = t_start + k * run.cycle
            run.idle_until(t_cycle)
            t = run.clock.now() - t_start
            # (Time spent waiting for an answer that did not come, a lost read retried, is
            # the bus's, not a stall.)
            stalled = t - last_t - run.cycle if last_t is not None and not waited else 0.0
            if last_t is not None and stalled > self.STALL_CYCLES * run.cycle:
                # This process was not run (a loaded PC): nothing was commanded meanwhile
                # and the joints went on to their last targets, then stopped. Resume the
                # plan where the arm is, so that it does not run ahead of the arm and
                # count a lag the arm never had as a following error.
                measured = run.read_arm().user_deg
                t_arm = plan_time_of(plan, measured, moving, last_t, t)
                held = t - t_arm
                t_start, t = t_start + held, t_arm
                k = int(t / run.cycle)  # the cycle slots move with the plan
                self.stalls.append(stalled)
                run.emit("host_stall", seconds=round(stalled, 4), held_s=round(held, 4),
                         plan_t=round(t, 4))
            last_t = t
            run.check_halt_request()
            if stop_on_abort and stops.aborts:
                self.controlled_stop(plan, t, moving)
                raise OperatorAbort("operator abort: controlled stop, arm holding")
            retries = run.bus_retries
            planned_rad, planned_vel, _ = plan.at(t)
            planned_deg = np.degrees(planned_rad)
            run.setpoint_deg = planned_deg  # (what a monitor's following error is against)
            m = self.cycle(plan, t, moving, measured)
            waited = run.bus_retries != retries
            measured = m.user_deg
            run.check_states(m)
            run.check_guards(m)
            if self.path_check is not None:
                self.path_check(m)
            error = np.abs(planned_deg - measured)
            if path_tolerance_deg is not None and t <= plan.duration:
                self.check_path_tolerance(plan, t, moving, measured, error,
                                          path_tolerance_deg)
            worst = int(error.argmax())  # (np.argmax's Python-level dispatch, once a cycle)
            if error[worst] > bound and t <= plan.duration + run.arm.control.settle_timeout_s:
                name = run.arm.joints[worst].name
                raise RunAborted("following_error",
                                 f"{name} (module {run.modules[worst]}) does not follow its "
                                 f"plan: {error[worst]:.2f}° from the planned position (limit "
                                 f"{bound}°)" + run.checks.lag_diagnosis(
                                     plan, planned_deg, measured, moving, run.command_mode),
                                 module=run.modules[worst])
            logged_planned, logged_measured = rounded(planned_deg), rounded(measured)
            event_t = round(run.elapsed_s(), 6)
            # When the joints answered (the bus's own stamps): after a host stall the
            # event's time is late, the reading's is not.
            read_t = self.read_t(m)
            if self.tracking is not None:
                # The figures come from the logged values, so events.jsonl reproduces them.
                self.tracking.add(read_t, logged_planned, logged_measured)
            run.emit("setpoint", t=event_t, read_t=read_t, plan_t=round(t, 4),
                     planned_deg=logged_planned, measured_deg=logged_measured,
                     planned_vel_deg_s=rounded(np.degrees(planned_vel), 2),
                     state=run.states_of(m))
            if t >= plan.duration:
                final_error = np.abs(np.degrees(plan.target) - measured)[moving]
                allowed = (tolerance_deg[moving] if isinstance(tolerance_deg, np.ndarray)
                           else tolerance_deg)
                if np.all(final_error <= allowed):
                    return
                if t > deadline and goal:
                    assert isinstance(tolerance_deg, np.ndarray)
                    over = final_error - allowed
                    i = moving[int(np.argmax(over))]
                    raise RunAborted(
                        "goal_tolerance",
                        f"{GOAL_TOLERANCE_VIOLATED}: {run.arm.joints[i].name} (module "
                        f"{run.modules[i]}) {abs(np.degrees(plan.target[i]) - measured[i]):.3f}° "
                        f"from its goal {t - plan.duration:.2f} s after the trajectory's end "
                        f"(goal tolerance {tolerance_deg[i]:g}°)", module=run.modules[i])
                if t > deadline:
                    i = moving[int(np.argmax(final_error))]
                    raise RunAborted("timeout",
                                     f"{run.arm.joints[i].name} (module {run.modules[i]}) not "
                                     f"in position {deadline:.1f} s after the move started: "
                                     f"{float(np.max(final_error)):.2f}° off (tolerance "
                                     f"{tolerance_deg}°)", module=run.modules[i])
            # Next cycle slot; slots missed while waiting on the bus are skipped, not
            # made up in a burst.
            k = max(k + 1, math.ceil((run.clock.now() - t_start) / run.cycle))

    def check_path_tolerance(self, plan: MovePlan, t: float, moving: list[int],
                             measured: np.ndarray, error: np.ndarray,
                             tolerance: np.ndarray) -> None:
        """A joint beyond its path tolerance: a controlled stop, then RunAborted
        (PATH_TOLERANCE_VIOLATED, the joint, its error and the plan time) so that the run
        ends as every fault does."""
        over = error - tolerance
        i = int(over.argmax())
        if over[i] <= 0:
            return
        run = self.run
        name = run.arm.joints[i].name
        message = (f"{PATH_TOLERANCE_VIOLATED}: {name} (module {run.modules[i]}) "
                   f"{error[i]:.3f}° from its setpoint at t={t:.2f} s of the trajectory's "
                   f"{plan.duration:.2f} s (path tolerance {tolerance[i]:g}°)")
        try:
            # from where the joints are (JTC holds the measured state): a lagging joint is
            # not driven to where it should have been
            self.controlled_stop(plan, t, moving, from_deg=measured)
        except RunAborted as stop:
            message += f"; the controlled stop did not end in position ({stop})"
        else:
            message += "; controlled stop"
        raise RunAborted("path_tolerance", message, module=run.modules[i])

    #: A gap between two cycles longer than (1 + this) cycles is a host stall: the plan is
    #: held for the time beyond one cycle.
    STALL_CYCLES = 1.0

    #: Joints that answered further apart than this (s) in one reading get a time each in
    #: the log (a host stall split the cycle's exchange); closer, one time stands for all.
    READ_SPREAD_S = 0.002

    def read_t(self, m: Measurement) -> float | list[float]:
        """A reading's time as logged (``read_t``): s since the run start, one for all
        joints, or one per joint when they answered far apart."""
        run = self.run
        if m.answered_at is None:
            return round(run.since_start(m.t), 6)
        at = [run.since_start(float(x)) for x in m.answered_at]
        if max(at) - min(at) > self.READ_SPREAD_S:
            return [round(x, 6) for x in at]
        return round(sum(at) / len(at), 6)

    def controlled_stop(self, plan: MovePlan, t: float, moving: list[int],
                        from_deg: np.ndarray | None = None) -> None:
        """ruckig to zero velocity from the plan's current state, streamed, then hold.
        ``from_deg``: start from these positions (where the arm was measured, a joint
        that lags its plan) with the plan's velocities."""
        run = self.run
        pos, vel, acc = plan.at(t)
        if from_deg is not None:
            pos = np.radians(from_deg)
        velocity, acceleration = run.limits_in_force.maxima()
        limits = Limits.from_arm(run.arm, speed=run.speed, max_velocity_deg_s=velocity,
                                 max_acceleration_deg_s2=acceleration)
        stop = plan_stop(pos, vel, acc, limits, moving)
        run.emit("controlled_stop", duration_s=_round(stop.duration))
        tol = run.arm.control.position_tolerance_deg
        self.stream(stop, moving, max(tol, 0.5), stop.duration + 2.0, stop_on_abort=False)
        run.emit("holding", joints_deg=rounded(run.last.user_deg) if run.last else None)

    # ------------------------------------------------------------------ waiting
    def wait(self, seconds: float) -> None:
        """Wait while monitoring every cycle (keeps faults and watchdog in view)."""
        run = self.run
        end = run.clock.now() + seconds
        while run.clock.now() < end:
            run.monitor()
            if run.stops.aborts:
                raise OperatorAbort("operator abort during a wait")
            run.idle(min(run.cycle, end - run.clock.now()))

    def wait_in_position(self, tolerance_deg: float, timeout_s: float) -> float:
        """Wait until every commanded joint is within tolerance; returns the time taken."""
        run = self.run
        start = run.clock.now()
        target = run.commanded_deg
        while True:
            m = run.monitor()
            if target is None:
                return 0.0
            err = np.abs(m.user_deg - target)[run.movable]
            if np.all(err <= tolerance_deg):
                return run.clock.now() - start
            if run.stops.aborts:
                raise OperatorAbort("operator abort during a wait")
            if run.clock.now() - start > timeout_s:
                i = run.movable[int(np.argmax(err))]
                raise RunAborted("timeout", f"{run.arm.joints[i].name} not in position within "
                                 f"{timeout_s} s: {float(np.max(err)):.2f}° off",
                                 module=run.modules[i])
            run.idle(run.cycle)
