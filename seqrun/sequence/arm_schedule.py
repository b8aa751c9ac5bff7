"""The arms of a campaign sequence on one planned time line, and checked against each other.

Each arm's track (:mod:`seqrun.sequence.arm_tracks`) is validated on its own; this puts the
tracks on one clock from their planned trajectories: a move lasts its plan, a ``wait`` its
seconds, a ``wait_for`` ends when the event's ``signal`` comes on the other arm (the other
steps take no planned time). That finds what the order cannot do (an event nobody
signals, signalled twice, arms waiting for each other, a wait that would time out) and
gives both arms' joints at the same instants, along which their volumes (link capsules and
tools, :mod:`seqrun.arm.between_arms`) are checked against each other in the facility
frame every :data:`~seqrun.sequence.validation.PLAN_SAMPLE_S` seconds. The smallest
clearance is reported like the guard clearances; below the arm files' geometry margin
the sequence is refused at the step that first moves into it.

That time line takes every step that waits for the operator or the modules (``confirm``,
``reset``, ``home``, ``wait: {until: in_position}``, ...) as 0 s. A run may take any time
there, so each such step is an unknown delay (:mod:`seqrun.sequence.arm_timing`): where it
leaves the offset between two stretches of the arms' tracks unknown, the stretches are
checked for *every* offset they can take (each arm's path swept over the window in which
the other can be anywhere along its own, :func:`seqrun.arm.between_arms.swept`), and a
meeting is refused at that step, with the hint to order the arms with signal/wait_for.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from seqrun.errors import SourceError
from seqrun.sequence.arm_timing import Stamp, offset_range, rigid, uncertain_delays
from seqrun.sequence.validation import PLAN_SAMPLE_S, ValidationResult
from seqrun.steps.resolved import ResolvedStep

__all__ = ["ArmPlan", "ArmsClearance", "Schedule", "check_arms", "schedule"]


@dataclass
class ArmPlan:
    """One arm's part in the checks: its track validated from its start."""

    arm_id: str
    arm: Any                    # ArmDescription
    base: np.ndarray            # 4x4, the base frame in the facility frame (mm)
    loaded: Any                 # LoadedSequence (its track)
    result: ValidationResult
    start_deg: dict[str, float]


@dataclass(frozen=True)
class ArmsClearance:
    """The smallest clearance between two arms' volumes along the planned time line."""

    pair: str                   # "A.forearm~B.wrist"
    distance_mm: float
    t_s: float                  # on the campaign's planned time line
    margin_mm: float
    steps: dict[str, str]       # arm -> "step 5 (Approach) moving" under way then

    def as_dict(self) -> dict:
        return {"pair": self.pair, "distance_mm": round(self.distance_mm, 2),
                "t_s": round(self.t_s, 3), "margin_mm": self.margin_mm,
                "steps": dict(self.steps)}

    def text(self) -> str:
        a, b = self.pair.split("~", 1)
        during = ", ".join(f"arm {arm}: {what}" for arm, what in self.steps.items())
        return (f"closest between arms: {a} - {b} {self.distance_mm:.1f} mm (link volumes, "
                f"facility frame), at {self.t_s:.2f} s ({during})")


@dataclass
class Stretch:
    """A stretch of one arm's track: a move (its planned path, ``times`` from its start)
    or a rest (one configuration) from ``start`` to ``end`` (None: to the run's end)."""

    start: Stamp
    end: Stamp | None
    times: np.ndarray
    q: np.ndarray
    step: ResolvedStep | None
    moving: bool


@dataclass
class _Timeline:
    times: list[float]
    q: list[np.ndarray]
    spans: list[tuple[float, float, ResolvedStep, bool]] = field(default_factory=list)
    t: float = 0.0
    index: int = 0
    #: When the arm gets here, for every timing the run can take.
    stamp: Stamp = field(default_factory=Stamp.zero)
    stretches: list[Stretch] = field(default_factory=list)
    #: The rest the arm is in (where, since when, after which step).
    rest: tuple[np.ndarray, Stamp, ResolvedStep | None] | None = None

    def moves(self, step: ResolvedStep, times: np.ndarray, q: np.ndarray,
              seconds: float) -> None:
        if self.rest is not None:
            where, since, after = self.rest
            self.stretches.append(Stretch(since, self.stamp, np.zeros(1), where[None, :],
                                          after, False))
        self.stretches.append(Stretch(self.stamp, self.stamp.plus(seconds),
                                      np.asarray(times, dtype=float), np.asarray(q), step,
                                      True))
        self.rest = (np.asarray(q)[-1], self.stamp.plus(seconds), step)

    def ends(self) -> None:
        if self.rest is not None:
            where, since, after = self.rest
            self.stretches.append(Stretch(since, None, np.zeros(1), where[None, :], after,
                                          False))
            self.rest = None


@dataclass
class Schedule:
    """The planned time line of every arm, and what the order could not do."""

    timelines: dict[str, _Timeline]
    end_s: float
    errors: list[SourceError]
    #: When each event is signalled (s on the time line).
    signals: dict[str, float]
    #: The steps of unknown duration: delay id -> (step, arm, largest value s or inf).
    delays: dict[int, tuple[ResolvedStep, str, float]] = field(default_factory=dict)

    @property
    def bounds(self) -> dict[int, float]:
        return {d: bound for d, (_, _, bound) in self.delays.items()}


def _unknown_duration(step: ResolvedStep) -> float | None:
    """The largest extra time (s; inf: unbounded) a step can take beyond its planned
    duration, None when it takes exactly that (a move's plan, ``wait: N``) or its end is
    worked out from the others (``signal``, ``wait_for``)."""
    if step.kind in ("signal", "wait_for"):
        return None
    if step.kind == "wait":
        if getattr(step.params, "seconds", None) is not None:
            return None
        timeout = getattr(step.params, "timeout_s", None)
        return float(timeout) if timeout is not None else float("inf")
    return float("inf")


def _duration(step: ResolvedStep, result: ValidationResult) -> tuple[float, Any]:
    path = result.paths.get(step.number)
    if path is not None:
        times, _ = path
        return float(times[-1]) if len(times) else 0.0, path
    seconds = getattr(step.params, "seconds", None)
    if step.kind == "wait" and seconds is not None:
        return float(seconds), None
    return 0.0, None


def schedule(plans: list[ArmPlan]) -> Schedule:
    """Walk every arm's track on one clock (see the module doc)."""
    lines: dict[str, _Timeline] = {}
    for plan in plans:
        q0 = np.radians([plan.start_deg.get(n, 0.0) for n in plan.arm.joint_names])
        lines[plan.arm_id] = _Timeline([0.0], [q0])
        lines[plan.arm_id].rest = (q0, Stamp.zero(), None)
    signals: dict[str, float] = {}
    signal_stamps: dict[str, Stamp] = {}
    delays: dict[int, tuple[ResolvedStep, str, float]] = {}
    signal_steps: dict[str, ResolvedStep] = {}
    errors: list[SourceError] = []
    by_id = {p.arm_id: p for p in plans}
    progressed = True
    while progressed:
        progressed = False
        for arm_id, line in lines.items():
            plan = by_id[arm_id]
            steps = plan.loaded.steps
            while line.index < len(steps):
                step = steps[line.index]
                if step.kind == "wait_for":
                    event = step.params.event
                    if event not in signals:
                        break
                    come = signals[event]
                    timeout = step.params.timeout_s
                    if timeout is not None and come - line.t > timeout + 1e-9:
                        errors.append(step.error(
                            f"'{event}' comes {come - line.t:.2f} s after arm {arm_id} gets "
                            f"here (planned), later than timeout_s {timeout:g} s",
                            "timeout_s"))
                    start = line.t
                    line.t = max(line.t, come)
                    line.stamp = line.stamp.later(signal_stamps[event])
                    line.spans.append((start, line.t, step, False))
                elif step.kind == "signal":
                    event = step.params.event
                    if event in signals:
                        first = signal_steps[event].location
                        errors.append(step.error(
                            f"'{event}' is signalled twice (first at {first}); an event "
                            "is signalled once per run", "event"))
                    else:
                        signals[event] = line.t
                        signal_stamps[event] = line.stamp
                        signal_steps[event] = step
                    line.spans.append((line.t, line.t, step, False))
                else:
                    seconds, path = _duration(step, plan.result)
                    start = line.t
                    if path is not None:
                        times, q = path
                        line.times.extend((start + np.asarray(times)).tolist())
                        line.q.extend(np.asarray(q))
                        if len(times):
                            line.moves(step, times, q, seconds)
                    line.stamp = line.stamp.plus(seconds)
                    extra = _unknown_duration(step) if path is None else None
                    if extra is not None:
                        delay = len(delays)
                        delays[delay] = (step, arm_id, extra)
                        line.stamp = line.stamp.delayed(delay)
                    line.t = start + seconds
                    line.spans.append((start, line.t, step, path is not None))
                line.index += 1
                progressed = True
    for arm_id, line in lines.items():
        steps = by_id[arm_id].loaded.steps
        if line.index >= len(steps):
            continue
        step = steps[line.index]
        event = step.params.event
        where = next((s.location for p in plans for s in p.loaded.steps
                      if s.kind == "signal" and s.params.event == event), None)
        if event.startswith("~"):
            errors.append(step.error(
                f"arm {arm_id} would wait here for ever: the step before, on another arm, "
                "waits for an event this arm signals only later"))
        elif where is not None:
            errors.append(step.error(
                f"arm {arm_id} would wait here for ever: '{event}' is signalled at {where} "
                "only after this step (the steps run in the order written; signal it "
                "earlier or put both in one parallel block)", "event"))
        else:
            errors.append(step.error(f"no step of any arm signals '{event}'", "event"))
    for line in lines.values():
        line.ends()
    end = max((line.t for line in lines.values()), default=0.0)
    return Schedule(lines, end, errors, signals, delays)


def _sample(line: _Timeline, grid: np.ndarray) -> np.ndarray:
    times = np.asarray(line.times)
    index = np.searchsorted(times, grid, side="right") - 1
    return np.asarray(line.q)[np.clip(index, 0, len(times) - 1)]


def _under_way(line: _Timeline, t: float) -> tuple[ResolvedStep | None, bool]:
    moving = [step for s, e, step, motion in line.spans if motion and s <= t <= e]
    if moving:
        return moving[-1], True
    done = [step for s, e, step, _ in line.spans if s <= t]
    return (done[-1] if done else None), False


def _during(planned: Schedule, pair: tuple[ArmPlan, ArmPlan], t: float) -> dict[str, str]:
    steps = {}
    for plan in pair:
        step, moving = _under_way(planned.timelines[plan.arm_id], t)
        steps[plan.arm_id] = (f"step {step.number} ({step.title})" if step is not None
                              else "at its start") + (" moving" if moving else "")
    return steps


def _refusal(planned: Schedule, pair: tuple[ArmPlan, ArmPlan], early: Any, t: float,
             margin: float, smallest: ArmsClearance) -> SourceError:
    """The error at the step that first moves the arms closer than the margin (the
    later-started one when both move), with the smallest clearance of the whole line."""
    under = {p.arm_id: _under_way(planned.timelines[p.arm_id], t) for p in pair}
    moving = [step for step, m in under.values() if m and step is not None]
    blamed = moving[-1] if moving else next(
        (step for step, _ in under.values() if step is not None), None)
    a, b = early.pair.split("~", 1)
    how = "into" if early.distance_mm < 0 else f"within {early.distance_mm:.1f} mm of"
    during = ", ".join(f"arm {k}: {v}" for k, v in _during(planned, pair, t).items())
    message = (f"the arms' paths cross: {a} comes {how} {b} at {t:.2f} s of the planned "
               f"time line ({during}); the arm files' geometry margin is {margin:g} mm "
               f"(closest: {smallest.distance_mm:.1f} mm at {smallest.t_s:.2f} s)")
    if blamed is None:
        return pair[0].loaded.location.error(message)
    return blamed.error(message)


def _why(step: ResolvedStep) -> str:
    if step.kind == "confirm":
        return "waits for the operator's answer"
    if step.kind == "wait":
        return "waits until the arm is in position"
    return f"takes as long as the modules take ({step.kind})"


def _stretch_text(arm_id: str, stretch: Stretch) -> str:
    step = stretch.step
    if stretch.moving and step is not None:
        return f"arm {arm_id}: step {step.number} ({step.title}) moving"
    if step is None:
        return f"arm {arm_id}: at its start"
    return f"arm {arm_id}: where step {step.number} ({step.title}) left it"


def _culprit(delays: set[int], first: Stamp, second: Stamp) -> int | None:
    """The step to blame for an unknown offset between two moments: a delay that one of
    them always waits for and the other never (the latest such), else the latest of
    those that differ."""
    def always(stamp: Stamp, d: int) -> bool:
        return all(d in s for s, _ in stamp.terms)

    def never(stamp: Stamp, d: int) -> bool:
        return not any(d in s for s, _ in stamp.terms)

    strong = [d for d in delays if (always(first, d) and never(second, d))
              or (always(second, d) and never(first, d))]
    if strong:
        return max(strong)
    return max(delays) if delays else None


def _unknown_timing(planned: Schedule, pair: tuple[ArmPlan, ArmPlan], geometry: dict,
                    margin: float) -> list[SourceError]:
    """Stretches of two arms whose offset a step of unknown duration leaves open, checked
    for every offset they can take (the module doc); one error per such step."""
    from seqrun.arm.between_arms import swept, swept_clearance

    first, second = pair
    bounds = planned.bounds
    cache: dict[int, Any] = {}

    def sweep(plan: ArmPlan, stretch: Stretch) -> Any:
        key = id(stretch)
        if key not in cache:
            until = None
            if not stretch.moving:
                until = (offset_range(stretch.end, stretch.start, bounds)[1]
                         if stretch.end is not None else float("inf"))
            per = max(1, int(round(0.1 / PLAN_SAMPLE_S)))
            cache[key] = swept(geometry[plan.arm_id], plan.base, stretch.times, stretch.q,
                               per=per, until_s=until)
        return cache[key]

    errors: dict[int, SourceError] = {}
    for sa in planned.timelines[first.arm_id].stretches:
        for sb in planned.timelines[second.arm_id].stretches:
            # never at the same time: one always ends before the other starts
            if sa.end is not None and offset_range(sa.end, sb.start, bounds)[1] <= 1e-9:
                continue
            if sb.end is not None and offset_range(sb.end, sa.start, bounds)[1] <= 1e-9:
                continue
            same = [(sa.start, sb.start)]
            same += [(sa.end, sb.start)] if sa.end is not None else []
            same += [(sb.end, sa.start)] if sb.end is not None else []
            if rigid(same, bounds):
                continue  # the planned time line is every run's: checked along it
            culprits = uncertain_delays(sa.start, sb.start, *(
                [sa.end] if sa.end is not None else []), *(
                [sb.end] if sb.end is not None else []))
            culprit = _culprit(culprits, sa.start, sb.start)
            if culprit in errors:
                continue
            lo, hi = offset_range(sb.start, sa.start, bounds)
            wa, wb = sweep(first, sa), sweep(second, sb)
            # stretch i of A [a0, a1] and j of B [b0, b1] (each from its own start) meet
            # for some offset of B's start after A's in [lo, hi]
            can_meet = ((wa.start_s[:, None] - wb.end_s[None, :] <= hi)
                        & (wa.end_s[:, None] - wb.start_s[None, :] >= lo))
            found = swept_clearance((first.arm_id, geometry[first.arm_id], wa),
                                    (second.arm_id, geometry[second.arm_id], wb), can_meet)
            if found is None or found[0] >= margin or culprit is None:
                continue
            distance, names, _, _ = found
            step, arm_id, _ = planned.delays[culprit]
            a, b = names.split("~", 1)
            how = "into" if distance < 0 else f"within {distance:.1f} mm of"
            errors[culprit] = step.error(
                f"arm {arm_id}: this step {_why(step)}, so from here the arms' timing is "
                f"not known: for some timing {a} comes {how} {b} "
                f"({_stretch_text(first.arm_id, sa)}, {_stretch_text(second.arm_id, sb)}); "
                f"the arm files' geometry margin is {margin:g} mm. Order the arms with "
                "signal/wait_for (the other arm waits for an event this arm signals) so "
                "that these stretches cannot meet")
    return list(errors.values())


def check_arms(plans: list[ArmPlan]) -> tuple[list[SourceError], list[ArmsClearance],
                                              Schedule]:
    """The order's findings and the arms' volumes against each other (see the module
    doc): ``(errors, smallest clearance of each pair of arms, schedule)``."""
    from seqrun.arm.between_arms import between_arms
    from seqrun.arm.geometry import Geometry

    planned = schedule(plans)
    errors = list(planned.errors)
    clearances: list[ArmsClearance] = []
    if errors or len(plans) < 2:
        return errors, clearances, planned
    count = max(2, int(np.ceil(planned.end_s / PLAN_SAMPLE_S)) + 1)
    grid = np.linspace(0.0, planned.end_s, count)
    geometry = {p.arm_id: Geometry(p.arm) for p in plans}
    for i, first in enumerate(plans):
        for second in plans[i + 1:]:
            qa = _sample(planned.timelines[first.arm_id], grid)
            qb = _sample(planned.timelines[second.arm_id], grid)
            margin = max(first.arm.geometry.margin_mm, second.arm.geometry.margin_mm)
            found = between_arms((first.arm_id, geometry[first.arm_id], first.base),
                                 (second.arm_id, geometry[second.arm_id], second.base),
                                 qa, qb, below_mm=margin)
            if found is None:
                continue
            smallest, early = found
            t = float(grid[smallest.index])
            clearance = ArmsClearance(smallest.pair, smallest.distance_mm, t, margin,
                                      _during(planned, (first, second), t))
            clearances.append(clearance)
            if early is not None:
                errors.append(_refusal(planned, (first, second), early,
                                       float(grid[early.index]), margin, clearance))
            errors += _unknown_timing(planned, (first, second), geometry, margin)
    return errors, clearances, planned
