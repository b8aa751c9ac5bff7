"""Arm against arm while they move: the one place every face's motions and every run's
control cycles check one arm's volumes against the others' (docs/two-arms.md).

:class:`Separation` holds the arms of one process (a campaign run, the console of several
arms) in the facility frame, each with its latest *measured* joints:

- **Every control cycle** (:meth:`ArmWatch.check`, called by each arm's executor with its
  reading) an arm's capsules at its measured joints are checked against every other
  arm's latest reading, each grown by the distance that arm can still travel before it
  stands: one cycle of reaction (plus the age of its reading) at its measured speed and
  the braking distance v^2/2a at the arm file's accelerations (ISO/TS 15066 speed and
  separation, :func:`seqrun.arm.between_arms.stopping_travel_mm`). Closer than that, both
  arms are halted (the other by a Halt request, this one by its fault): exit 3, the fault
  naming the two arms and the clearance.
- **After a fault** with ``on_fault = "halt_faulted"``, :meth:`Separation.clear_of_stopped`
  says whether another arm's remaining planned motion (its executor's plan from the step
  under way on) stays clear of the faulted arm where it stopped; if not, it halts too.
- **Before a motion of a face** (console, ROS), :meth:`Separation.refusal` checks the
  planned joints of one arm against the others' measured pose and, while they move,
  their remaining plans: one line naming the other arm and the clearance, or None.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from seqrun.errors import Refused, RunAborted

__all__ = ["ARMS_TOO_CLOSE", "ArmWatch", "SessionSeparation", "Separation",
           "attach_other_arms", "attach_sessions", "bases_of_project", "remaining_plan"]

#: How far ahead a jog is checked against the other arms (s, beyond its dead-man period):
#: the jog is watched every cycle after that.
JOG_LOOKAHEAD_S = 1.0

#: The fault cause of arms halted because they came too close to each other.
ARMS_TOO_CLOSE = "arms_too_close"


@dataclass
class _Reading:
    t: float
    q_rad: np.ndarray
    v_rad_s: np.ndarray
    cycle_s: float
    #: The arm's capsule segments there, facility frame (worked out once per reading).
    volumes: np.ndarray | None = None
    #: Where each joint stops if no command follows (user rad, NaN: not commanded);
    #: None: not bounded.
    holds_at_rad: np.ndarray | None = None


class _Arm:
    """One arm's fixed parts: geometry, base, levers, decelerations."""

    def __init__(self, arm_id: str, arm: Any, base: np.ndarray) -> None:
        from seqrun.arm.between_arms import levers_mm
        from seqrun.arm.geometry import Geometry

        self.arm_id = arm_id
        self.arm = arm
        self.base = np.asarray(base, dtype=float)
        self.geometry = Geometry(arm)
        self.levers = levers_mm(self.geometry)
        self.deceleration = np.radians([j.max_acceleration_deg_s2 for j in arm.joints])
        self.max_velocity = np.radians([j.max_velocity_deg_s for j in arm.joints])
        self.margin_mm = float(arm.geometry.margin_mm)

    def volumes(self, q_rad: np.ndarray) -> np.ndarray:
        """Capsule segments ``(k, capsules, 2, 3)`` of configurations ``(k, dof)``, or
        ``(capsules, 2, 3)`` of one configuration ``(dof,)``."""
        from seqrun.arm.between_arms import volumes_in_facility

        return volumes_in_facility(self.geometry, self.base, q_rad)

    def travel_mm(self, reading: _Reading, extra_s: float = 0.0) -> float:
        """How far the arm can go from ``reading`` before it stands, ``extra_s`` after it
        (the reading's age): a joint under a position command goes no farther than its
        target plus one more cycle's command, however long its host is silent."""
        from seqrun.arm.between_arms import stopping_travel_mm

        holds = reading.holds_at_rad
        return stopping_travel_mm(
            reading.v_rad_s, self.deceleration, reading.cycle_s + max(0.0, extra_s),
            self.levers, rest_gap_rad=None if holds is None else holds - reading.q_rad,
            next_command_rad=self.max_velocity * reading.cycle_s)


def bases_of_project(project: Any, arm_ids: Any) -> dict[str, np.ndarray]:
    """Each arm's base frame in the facility frame from the campaign's ``[arms.ID] base``
    (missing: the facility frame)."""
    from seqrun.arm.between_arms import base_of

    config = getattr(project, "config", None)
    arms = getattr(config, "arms", None) or {}
    return {a: base_of(arms[a].base if a in arms else None) for a in arm_ids}


class Separation:
    """The arms of one process against each other (module doc). Thread-safe: each arm's
    loop reports on its own thread."""

    def __init__(self, arms: Mapping[str, Any], bases: Mapping[str, np.ndarray]) -> None:
        self._arms = {a: _Arm(a, arm, bases.get(a, np.eye(4))) for a, arm in arms.items()}
        self._lock = threading.Lock()
        self._readings: dict[str, _Reading] = {}
        #: Each arm's way to be halted (its executor's halt) while a run drives it.
        self._halts: dict[str, Callable[[str, str], None]] = {}
        #: Each arm's remaining planned joints and speeds (rad, rad/s, (k, dof) each)
        #: while a run drives it, if known.
        self._plans: dict[str, Callable[[], tuple[np.ndarray, np.ndarray] | None]] = {}
        #: Where an arm stands when no run of this process reports it (user degrees of
        #: every joint, None: not known): a session's telemetry, another process's arm.
        self._where: dict[str, Callable[[], Any]] = {}
        #: Those of them too slow for a control cycle (another process's arm): asked
        #: before a motion only; what they said then stands for the cycles after.
        self._slow: set[str] = set()
        #: Set once the arms were halted for coming too close (what was said).
        self.tripped: str | None = None

    @property
    def arm_ids(self) -> tuple[str, ...]:
        return tuple(self._arms)

    def stands_at(self, arm_id: str, where: Callable[[], Any], *,
                  every_cycle: bool = True) -> None:
        """``where()``: arm ``arm_id``'s measured joints (user degrees) when asked;
        ``every_cycle=False``: too slow to ask every control cycle (another process's arm:
        asked before each motion, its answer standing for the cycles after)."""
        self._where[arm_id] = where
        if not every_cycle:
            self._slow.add(arm_id)

    # ------------------------------------------------------------------ readings
    def report(self, arm_id: str, t: float, user_deg: Any, cycle_s: float, *,
               holds_at_rad: np.ndarray | None = None) -> _Reading:
        """Arm ``arm_id`` was measured at ``user_deg`` at time ``t`` (s, the shared clock),
        its joints under position commands to ``holds_at_rad`` (see :class:`_Reading`):
        its speed is worked out from its reading before."""
        q = np.radians(np.asarray(user_deg, dtype=float))
        with self._lock:
            before = self._readings.get(arm_id)
            # (two readings less than half a cycle apart tell no speed: their difference
            # is the modules' resolution over a tiny time)
            if (before is not None and t - before.t >= 0.5 * cycle_s
                    and len(before.q_rad) == len(q)):
                v = (q - before.q_rad) / (t - before.t)
            else:
                v = before.v_rad_s if before is not None else np.zeros_like(q)
            reading = _Reading(t, q, v, cycle_s, holds_at_rad=holds_at_rad)
        me = self._arms[arm_id]
        if not me.geometry.empty:
            reading.volumes = me.volumes(q)
        with self._lock:
            self._readings[arm_id] = reading
        return reading

    def stopped(self, arm_id: str, user_deg: Any) -> None:
        """Arm ``arm_id`` stands at ``user_deg`` (a confirmed Halt)."""
        q = np.radians(np.asarray(user_deg, dtype=float))
        with self._lock:
            before = self._readings.get(arm_id)
            self._readings[arm_id] = _Reading(
                before.t if before is not None else 0.0, q, np.zeros_like(q),
                before.cycle_s if before is not None else 0.0,
                self._arms[arm_id].volumes(q) if not self._arms[arm_id].geometry.empty
                else None)

    def watch(self, arm_id: str, halt: Callable[[str, str], None] | None = None,
              plan: Callable[[], tuple[np.ndarray, np.ndarray] | None] | None = None
              ) -> ArmWatch:
        """The per-cycle check of ``arm_id`` (hand it to its executor); ``halt(reason,
        cause)`` halts that arm from any thread, ``plan()`` its remaining planned joints
        and speeds."""
        with self._lock:
            if halt is not None:
                self._halts[arm_id] = halt
            if plan is not None:
                self._plans[arm_id] = plan
        return ArmWatch(self, arm_id)

    def release(self, arm_id: str) -> None:
        """The arm's run ended: nobody halts it through here any more. Its last reading
        stays where it stands, unless something else tells where it stands (a session's
        telemetry, then at rest)."""
        with self._lock:
            self._halts.pop(arm_id, None)
            self._plans.pop(arm_id, None)
            if arm_id in self._where:
                self._readings.pop(arm_id, None)

    # ------------------------------------------------------------------ every cycle
    def closest(self, arm_id: str, reading: _Reading) -> tuple[float, str, str, float,
                                                              float] | None:
        """The smallest clearance of ``arm_id`` at ``reading`` to any other arm's latest
        reading less both arms' stopping travel: ``(grown clearance mm, other arm, pair,
        clearance mm, travel mm)``; None without another arm's reading. Where the arms'
        bounding spheres keep them apart by more than their travel, that lower bound is
        what is returned (the exact distances are worked out only when it is close)."""
        from seqrun.arm.between_arms import pair_clearance, sphere_gap

        me = self._arms[arm_id]
        with self._lock:
            others = {a: r for a, r in self._readings.items() if a != arm_id}
            idle = {a: w for a, w in self._where.items()
                    if a != arm_id and a not in others and a not in self._slow}
        for other_id, where in idle.items():  # no run reports it: where it stands (at rest)
            stands = where()
            if stands is not None:
                q = np.radians(np.asarray(stands, dtype=float))
                others[other_id] = _Reading(reading.t, q, np.zeros_like(q), 0.0,
                                            self._arms[other_id].volumes(q)
                                            if not self._arms[other_id].geometry.empty
                                            else None)
        if not others or me.geometry.empty:
            return None
        mine = reading.volumes if reading.volumes is not None else me.volumes(reading.q_rad)
        own_travel = me.travel_mm(reading)
        worst = None
        for other_id, theirs in others.items():
            other = self._arms[other_id]
            if other.geometry.empty:
                continue
            segments = theirs.volumes if theirs.volumes is not None \
                else other.volumes(theirs.q_rad)
            travel = own_travel + other.travel_mm(theirs, reading.t - theirs.t)
            d = sphere_gap(mine, me.geometry.radii_mm, segments, other.geometry.radii_mm)
            if float(d.min()) - travel < 0.0:
                d = pair_clearance(mine, me.geometry.radii_mm, segments,
                                   other.geometry.radii_mm)
            i, j = np.unravel_index(int(np.argmin(d)), d.shape)
            grown = float(d[i, j]) - travel
            if worst is None or grown < worst[0]:
                pair = (f"{arm_id}.{me.geometry.volume_names[i]}~"
                        f"{other_id}.{other.geometry.volume_names[j]}")
                worst = (grown, other_id, pair, float(d[i, j]), travel)
        return worst

    def trip(self, arm_id: str, found: tuple[float, str, str, float, float]) -> RunAborted:
        """Halt the other arm (a Halt request) and return this arm's fault."""
        _, other_id, pair, clearance, travel = found
        a, b = pair.split("~", 1)
        text = (f"arms {arm_id} and {other_id} too close: {a} {clearance:.1f} mm from {b} "
                f"(measured), within the {travel:.1f} mm both can still travel before they "
                "stand (reaction and braking at their speeds): both halted")
        with self._lock:
            halts = [h for a_, h in self._halts.items() if a_ != arm_id]
            if self.tripped is None:
                self.tripped = text
        for halt in halts:
            halt(text, ARMS_TOO_CLOSE)
        return RunAborted(ARMS_TOO_CLOSE, text)

    # ------------------------------------------------------------------ after a fault
    def clear_of_stopped(self, arm_id: str, stopped_id: str) -> tuple[bool, str]:
        """Whether ``arm_id``'s remaining planned motion (and where it stands) stays at
        least the geometry margin clear of ``stopped_id`` where it stands; and why."""
        from seqrun.arm.between_arms import pair_clearance

        me, other = self._arms[arm_id], self._arms[stopped_id]
        with self._lock:
            reading = self._readings.get(arm_id)
            stopped = self._readings.get(stopped_id)
            plan = self._plans.get(arm_id)
        if stopped is None:
            return False, f"where arm {stopped_id} stopped is not known"
        remaining = plan() if plan is not None else None
        if remaining is None:
            return False, f"arm {arm_id}'s remaining motion is not known"
        q, v = (np.atleast_2d(x) for x in remaining)
        if reading is not None:
            q = np.concatenate([q, reading.q_rad[None, :]])
            v = np.concatenate([v, reading.v_rad_s[None, :]])
        if me.geometry.empty or other.geometry.empty or not len(q):
            return True, "nothing of it can meet the other"
        from seqrun.arm.between_arms import stopping_travel_mm

        # what every cycle will check on the way (ArmWatch): clear by the margin beyond
        # the distance the arm needs to stop at its planned speed there
        cycle = reading.cycle_s if reading is not None else 0.0
        travel = np.array([stopping_travel_mm(vk, me.deceleration, cycle, me.levers)
                           for vk in v])
        d = pair_clearance(me.volumes(q), me.geometry.radii_mm[None, :],
                           other.volumes(stopped.q_rad)[None, :],
                           other.geometry.radii_mm[None, :])
        d = d - travel[:, None, None]
        k, i, j = np.unravel_index(int(np.argmin(d)), d.shape)
        margin = max(me.margin_mm, other.margin_mm)
        smallest = float(d[k, i, j])
        pair = (f"{arm_id}.{me.geometry.volume_names[i]} - "
                f"{stopped_id}.{other.geometry.volume_names[j]}")
        if smallest < margin:
            return False, (f"arm {arm_id}'s remaining motion comes within {smallest:.1f} mm "
                           f"of arm {stopped_id} where it stopped ({pair}, less its stopping "
                           f"distance; margin {margin:g} mm)")
        return True, (f"arm {arm_id}'s remaining motion stays {smallest:.1f} mm clear of "
                      f"arm {stopped_id} where it stopped ({pair}, less its stopping "
                      "distance)")

    def halt_others(self, arm_id: str, reason: str, cause: str = ARMS_TOO_CLOSE) -> None:
        """Halt ``arm_id`` through its run (a Halt request), if a run drives it."""
        with self._lock:
            halt = self._halts.get(arm_id)
        if halt is not None:
            halt(reason, cause)

    # ------------------------------------------------------------------ a face's motion
    def refusal(self, arm_id: str, q_rad: Any) -> str | None:
        """A face's planned motion of ``arm_id`` (joints rad, ``(k, dof)``, its path)
        against every other arm where it stands and, while that arm moves, its remaining
        plan: one line naming the other arm and the clearance when closer than the
        geometry margin, else None."""
        from seqrun.arm.between_arms import pair_clearance

        me = self._arms.get(arm_id)
        if me is None or me.geometry.empty:
            return None
        path = np.atleast_2d(np.asarray(q_rad, dtype=float))
        mine = me.volumes(path)  # (k, na, 2, 3)
        with self._lock:
            readings = dict(self._readings)
            plans = dict(self._plans)
        for other_id, other in self._arms.items():
            if other_id == arm_id or other.geometry.empty:
                continue
            where = self._where.get(other_id)
            stands = where() if where is not None else None
            if stands is not None:
                q_now = np.radians(np.asarray(stands, dtype=float))
                if other_id in self._slow:  # what the cycles after check against
                    with self._lock:
                        self._readings[other_id] = _Reading(
                            readings[arm_id].t if arm_id in readings else 0.0, q_now,
                            np.zeros_like(q_now), 0.0, other.volumes(q_now))
            elif other_id in readings:
                q_now = readings[other_id].q_rad
            else:
                return (f"refused: where arm {other_id} stands is not known, so this motion "
                        f"of arm {arm_id} cannot be checked against it; nothing was sent")
            theirs = [q_now[None, :]]
            plan = plans.get(other_id)
            remaining = plan() if plan is not None else None
            if remaining is not None and len(remaining[0]):
                theirs.append(np.atleast_2d(remaining[0]))
            q_other = np.concatenate(theirs)
            seg_b = other.volumes(q_other)  # (m, nb, 2, 3)
            margin = max(me.margin_mm, other.margin_mm)
            smallest, pair = np.inf, ""
            for at in range(0, len(mine), 32):  # (a few thousand pairs at a time)
                d = pair_clearance(mine[at:at + 32, None], me.geometry.radii_mm,
                                   seg_b[None, :], other.geometry.radii_mm)
                k, m, i, j = np.unravel_index(int(np.argmin(d)), d.shape)
                if d[k, m, i, j] < smallest:
                    smallest = float(d[k, m, i, j])
                    pair = (f"{arm_id}.{me.geometry.volume_names[i]} - "
                            f"{other_id}.{other.geometry.volume_names[j]}")
            if smallest < margin:
                place = "where it stands" if len(q_other) == 1 else "where it stands or moves"
                how = "into" if smallest < 0 else f"within {smallest:.1f} mm of"
                return (f"refused: arm {arm_id} would come {how} arm {other_id} {place} "
                        f"({pair} {smallest:.1f} mm; the arm files' geometry margin is "
                        f"{margin:g} mm); nothing was sent")
        return None


class ArmWatch:
    """One arm's per-cycle check (the executor's ``separation``)."""

    def __init__(self, separation: Separation, arm_id: str) -> None:
        self.separation = separation
        self.arm_id = arm_id

    def check(self, t: float, user_deg: Any, cycle_s: float, *,
              holds_at_rad: np.ndarray | None = None) -> None:
        """This arm's reading (its joints under position commands to ``holds_at_rad``):
        raises :class:`~seqrun.errors.RunAborted` (and halts the others) when the arms
        could touch before they stand."""
        separation = self.separation
        reading = separation.report(self.arm_id, t, user_deg, cycle_s,
                                    holds_at_rad=holds_at_rad)
        found = separation.closest(self.arm_id, reading)
        if found is not None and found[0] < 0.0:
            raise separation.trip(self.arm_id, found)


class SessionSeparation:
    """One arm session's part in a :class:`Separation` (``session.separation``: the
    console of several arms, ``seqrun ros --arm-id``): every motion a face asks of the
    session is checked against the other arms before it is sent, and the session's
    executors check every cycle."""

    def __init__(self, separation: Separation, arm_id: str) -> None:
        self.separation = separation
        self.arm_id = arm_id

    def refuse_paths(self, what: str, paths: Mapping[int, Any]) -> None:
        """Refused (one line naming the other arm and the clearance) when a planned path
        (step number -> (times, joints rad)) comes closer to another arm than the margin."""
        qs = [np.atleast_2d(np.asarray(q, dtype=float)) for _, q in paths.values() if len(q)]
        if not qs:
            return
        line = self.separation.refusal(self.arm_id, np.concatenate(qs))
        if line is not None:
            raise Refused(f"{what}: {line}")

    def refuse_jog(self, what: str, joints_deg: Any, index: int, end_deg: float,
                   velocity_deg_s: float, deadman_s: float) -> None:
        """A jog of joint ``index`` from ``joints_deg`` towards ``end_deg``: the stretch it
        can go before its dead-man ends it (and a margin of time) is checked like a path;
        beyond, every cycle watches it."""
        start = np.asarray(joints_deg, dtype=float)
        reach = abs(velocity_deg_s) * (deadman_s + JOG_LOOKAHEAD_S)
        span = float(np.clip(end_deg - start[index], -reach, reach))
        steps = max(2, int(abs(span) / 0.5) + 1)  # every half degree
        path = np.repeat(start[None, :], steps, axis=0)
        path[:, index] = start[index] + np.linspace(0.0, span, steps)
        self.refuse_paths(what, {0: (np.zeros(steps), np.radians(path))})

    def watch(self, executor: Any) -> None:
        """The session's executor checks this arm against the others every cycle, and its
        remaining plan counts for their motions while it runs."""
        separation, arm_id = self.separation, self.arm_id
        executor.separation = separation.watch(
            arm_id, halt=executor.halt, plan=lambda: remaining_plan(executor))

        def ended(event: Any) -> None:
            if getattr(event, "type", None) == "run_finished":
                separation.release(arm_id)
        executor.listeners.append(ended)


def remaining_plan(executor: Any) -> Any:
    """The joints (rad) an arm's run still plans to pass, and its planned speeds there
    (rad/s): every move's planned path from the step under way on, ``(q, v)`` each
    ``(k, dof)`` (None: not known yet)."""
    paths = executor.planned_paths
    if paths is None:
        return None
    step = executor.current_step
    first = step.number if step is not None else 0
    qs, vs = [], []
    for n in sorted(paths):
        times, q = (np.asarray(x, dtype=float) for x in paths[n])
        if n < first or not len(q):
            continue
        qs.append(q)
        vs.append(np.gradient(q, times, axis=0) if len(q) > 1 else np.zeros_like(q))
    if not qs:
        empty = np.empty((0, len(executor.arm.joints)))
        return empty, empty
    return np.concatenate(qs), np.concatenate(vs)


def _telemetry_joints(session: Any) -> Callable[[], Any]:
    def where() -> Any:
        measured = session.telemetry.joints_deg()
        names = session.arm.joint_names
        if any(n not in measured for n in names):
            return None
        return [measured[n] for n in names]
    return where


def attach_sessions(sessions: Mapping[str, Any], bases: Mapping[str, Any]) -> Separation:
    """The arms of one console: one :class:`Separation`, each session's part in it
    (``session.separation``), each arm's measured pose from its session's telemetry.
    ``bases``: each arm's base pose (``[arms.ID] base``; missing or None: the facility
    frame)."""
    from seqrun.arm.between_arms import base_of

    separation = Separation({a: s.arm for a, s in sessions.items()},
                            {a: base_of(bases.get(a)) for a in sessions})
    for arm_id, session in sessions.items():
        separation.stands_at(arm_id, _telemetry_joints(session))
        session.separation = SessionSeparation(separation, arm_id)
    return separation


def attach_other_arms(session: Any, context: Any) -> Separation | None:
    """``seqrun ros --arm-id B``: the other arms of the campaign are other processes' (or
    nobody's): their measured pose is asked when a motion is checked, from the seqrun that
    holds their bus (its control socket) or, when none does, read from their bus; an arm
    whose pose cannot be had refuses the motion. None: a campaign of one arm."""
    from seqrun.service.arm_context import campaign_arm_ids, resolve_context

    project = getattr(session, "project", None)
    ids = [str(a) for a in campaign_arm_ids(project)] if project is not None else []
    if context.arm_id is None or len(ids) < 2:
        return None
    contexts = {a: (context if a == str(context.arm_id) else
                    resolve_context(project=project, arm_id=a)) for a in ids}
    separation = Separation({a: c.arm for a, c in contexts.items()},
                            {a: c.base_transform() for a, c in contexts.items()})
    separation.stands_at(str(context.arm_id), _telemetry_joints(session))
    for arm_id, other in contexts.items():
        if arm_id != str(context.arm_id):
            separation.stands_at(arm_id, _elsewhere(other), every_cycle=False)
    session.separation = SessionSeparation(separation, str(context.arm_id))
    return separation


def _elsewhere(context: Any) -> Callable[[], Any]:
    """Another process's arm, read when asked as ``seqrun status`` reads it (None when it
    cannot be): the seqrun that holds its bus is asked over its control socket, else its
    bus is read under a short claim, with the zero reference in force."""
    def where() -> Any:
        from seqrun.service.arm_access import read_status
        from seqrun.service.bus_claim import claim_bus
        from seqrun.service.control_socket import ask_owner
        from seqrun.service.zero import zero_for_reading

        key = context.bus.key
        if key is None:
            return None  # a built-in simulator of another process: nobody can read it
        try:
            interface, channel = key
            reply = ask_owner(interface, channel, "status")
            if reply is not None:
                if not reply.get("ok", True) or not isinstance(reply.get("status"), dict):
                    return None
                joints = reply["status"].get("joints") or []
            else:
                claim = claim_bus(interface, channel, transient=True)
                try:
                    connection, driver = context.open_arm(claim=False)
                    try:
                        arm, _ = zero_for_reading(connection, context.arm)
                        joints = read_status(driver, arm)["joints"]
                    finally:
                        connection.close()
                finally:
                    claim.release()
            values = [j.get("position_deg") for j in joints]
            if len(values) != len(context.arm.joints) or any(v is None for v in values):
                return None
            return [float(v) for v in values]
        except Exception:  # noqa: BLE001 - not known: the motion is refused, said there
            return None
    return where
