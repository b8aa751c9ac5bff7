"""The checks of every reading of the arm while a run has it: state flags, workspace guards,
link volumes, and a fault named from the joint's own decoded state.

A joint whose reading says it refuses motion is asked its full state (through the driver);
a fault or a missing Home becomes a :class:`~seqrun.errors.RunAborted` naming the module,
the joint and the flags. Guards and link volumes are checked by forward kinematics of the
measured joints, and the smallest height and clearance are kept for the report.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from seqrun.arm import kinematics
from seqrun.errors import BusError, RunAborted

if TYPE_CHECKING:
    from seqrun.arm.geometry import Geometry
    from seqrun.arm.description import ArmDescription
    from seqrun.arm.planner import MovePlan
    from seqrun.arm.joint_values import JointState
    from seqrun.drivers.base import CycleState

#: Below this share of its planned travel a lagging joint counts as hardly moving.
SLOW_SHARE = 0.5
#: Travel (deg) below which a joint counts as not moving at all.
STILL_DEG = 0.02


class ReadingChecks:
    """The checks of one run's readings (module docstring). ``read_state(module)`` asks a
    module's full state (the executor's, through the driver)."""

    def __init__(self, arm: ArmDescription, chain: kinematics.Chain, read_state: Any) -> None:
        self.arm = arm
        self.chain = chain
        self.modules = arm.module_ids
        self.read_state = read_state
        #: Lowest height seen per guard and point ("guard:point"), mm.
        self.min_heights_mm: dict[str, float] = {}
        #: Smallest clearance seen per pair of link volumes / obstacles (the closest pair
        #: of each cycle), mm.
        self.min_distances_mm: dict[str, float] = {}
        self._geometry: Geometry | None = None
        self._watching: list[list[str]] | None = None

    # ------------------------------------------------------------------ state flags
    def check_states(self, short_state: dict[int, CycleState], *,
                     require_homed: bool = True) -> None:
        """Raise a RunAborted naming module and flags for a module whose reading says it
        refuses motion and whose full state shows a fault (or, with ``require_homed``, it
        is not homed)."""
        for module, state in short_state.items():
            if state.refuses_motion:
                flags = self.read_state(module)
                if flags.faulted or (require_homed and not flags.homed):
                    raise self.module_fault(module, flags)

    def fault_after_halt(self, module: int, short: CycleState) -> RunAborted:
        """The fault of a module whose acknowledge said NOT_OK during a move, named from
        its state word (read after the Halt)."""
        try:
            flags = self.read_state(module)
        except BusError as exc:
            return RunAborted("module_fault", f"module {module}: NOT_OK in its acknowledge "
                              f"[short state {short.describe()}]; its state word could not be "
                              f"read: {exc}", module=module)
        if not flags.ready:
            return self.module_fault(module, flags)
        joint = self.arm.joint_names[self.modules.index(module)]
        return RunAborted("motion_refused", f"module {module} ({joint}): refused a motion "
                          f"command during the move (NOT_OK in its acknowledge) "
                          f"[state {flags.describe()}]", module=module)

    def module_fault(self, module: int, flags: JointState, context: str = "") -> RunAborted:
        """A RunAborted naming the module, its joint and the decoded fault flags."""
        joint = self.arm.joint_names[self.modules.index(module)] if module in self.modules else "?"
        what = flags.fault_text if flags.faulted else "not homed (HOME_OK clear)"
        text = f"module {module} ({joint}): {what}"
        if context:
            text += f" {context}"
        return RunAborted(flags.cause, f"{text} [state {flags.describe()}]", module=module)

    # ------------------------------------------------------------------ where the arm is
    @property
    def geometry(self) -> Geometry:
        """The link and tool volumes (built at the first reading that needs them)."""
        if self._geometry is None:
            from seqrun.arm.geometry import Geometry

            self._geometry = Geometry(self.arm)
        return self._geometry

    def check_guards(self, user_deg: np.ndarray) -> None:
        """Workspace guards and link volumes at the measured joints."""
        q = np.radians(user_deg)
        self.check_geometry(q)
        guards = self.arm.workspace.guards
        if not guards:
            return
        tools = self.geometry.tools
        if not tools.parts:
            heights: dict[str, float] = kinematics.point_heights(  # type: ignore[assignment]
                self.chain, q)
            watching = self._watched_points(False)
        else:
            # a guard that watches the end-effector watches what the flange carries too
            found, tool_z = kinematics.heights_of_points(self.chain, q, tools.points_mm)
            heights = dict(found.items())
            heights["tool"], part = tools.lowest_z(tool_z)
            watching = self._watched_points(True)
        for guard, watched in zip(guards, watching):
            for name in watched:
                z = heights[name]
                key = f"{guard.name}:{name}"
                self.min_heights_mm[key] = min(self.min_heights_mm.get(key, math.inf), z)
                if z < guard.min_z_mm:
                    what = part if name == "tool" else name
                    raise RunAborted("workspace_guard",
                                     f"workspace guard '{guard.name}': {what} at z = {z:.1f} mm, "
                                     f"below {guard.min_z_mm:.1f} mm")

    def _watched_points(self, tools: bool) -> list[list[str]]:
        """Each guard's watched points (with "tool" where it watches the end-effector and
        the arm has tool volumes), worked out once per run."""
        if self._watching is None:
            self._watching = [
                [*guard.points, "tool"] if tools and "end_effector" in guard.points
                else list(guard.points) for guard in self.arm.workspace.guards]
        return self._watching

    def check_geometry(self, q_rad: np.ndarray) -> None:
        """Link volumes against the arm file's obstacles and each other (measured joints)."""
        geometry = self.geometry
        if geometry.empty:
            return
        smallest = geometry.smallest(q_rad)
        if smallest is None:
            return
        key = smallest.pair
        self.min_distances_mm[key] = min(self.min_distances_mm.get(key, math.inf),
                                         smallest.distance_mm)
        if smallest.distance_mm < geometry.margin_mm:
            a, b = smallest.pair.split("~", 1)
            raise RunAborted("collision",
                             f"geometry: {a} {smallest.distance_mm:.1f} mm from {b}, closer than "
                             f"the margin {geometry.margin_mm:g} mm")

    # ------------------------------------------------------------------ following the plan
    def lag_diagnosis(self, plan: MovePlan, planned_deg: np.ndarray, measured: np.ndarray,
                      moving: list[int], command_mode: str) -> str:
        """The likely cause of a following error, for the operator: every moving joint
        travelling the right way at a small share of its plan points at modules whose FRAMP
        does not blend (each FRAMP restarts from standstill), one joint not moving at all
        at a stuck or blocked joint."""
        start = np.degrees(plan.start)
        direction = np.sign(np.degrees(plan.target) - start)
        planned = (planned_deg - start) * direction
        done = (measured - start) * direction
        shares = {i: done[i] / planned[i] for i in moving if planned[i] > STILL_DEG}
        if not shares:
            return ""
        text = ", ".join(f"{self.arm.joints[i].name} {100 * r:.0f} %" for i, r in shares.items())
        if (command_mode == "ramp" and len(shares) == len(moving)
                and all(done[i] > STILL_DEG and r < SLOW_SHARE for i, r in shares.items())):
            return (f"; the module does not seem to blend FRAMP commands: every moving joint "
                    f"travels the right way at a small share of its plan ({text} of the "
                    f"planned travel), as if each FRAMP started from standstill (see "
                    f"docs/safety.md, 'FRAMP blending')")
        still = [self.arm.joints[i].name for i in shares if abs(done[i]) <= STILL_DEG]
        if still:
            return f"; {', '.join(still)} did not move at all (stuck, blocked or not enabled?)"
        return ""
