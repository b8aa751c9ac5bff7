"""Each motion step's hazard class, from its ``hazard`` key and its planned clearances.

A step's class is the higher of the one it gives (``hazard:``) and the one the arm file's
``hazards.*.within_mm`` derive from the move's smallest planned clearance (to a guard, an
obstacle, another link); giving a lower class than that is an error at the key. Steps of
class normal have no finding. docs/safety.md, "Hazard classes".
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from seqrun.arm.hazards import rank
from seqrun.formatting import format_number as _f

if TYPE_CHECKING:
    from seqrun.arm.description import ArmDescription
    from seqrun.errors import SourceError
    from seqrun.steps.resolved import ResolvedStep

__all__ = ["CAPPED_KINDS", "HazardFinding", "classify"]

#: The motion kinds the class's speed cap bounds (a fraction of the joints' velocity
#: limits): a move is planned at it, a straight line must stay within it; move_velocity
#: and move_trajectory give their own velocities and times.
CAPPED_KINDS = frozenset({"move", "move_linear"})


@dataclass(frozen=True)
class HazardFinding:
    """A step of class caution or hazardous: why, and what that means for its run."""

    step: int
    location: str
    hazard: str
    #: Why: "given in the step" or "within 42 mm of guard desk".
    reason: str
    #: The class's speed cap (1.0: none applies to this kind of step).
    speed_scale: float
    #: Who signs before a hazardous step (None: whoever is at the run).
    role: str | None

    @property
    def needs_signature(self) -> bool:
        return self.hazard == "hazardous"

    def line(self) -> str:
        """"step 5 (FILE:L:C): hazardous — within 42 mm of guard desk; speed capped at
        25 %; needs a signed confirm\""""
        parts = [self.reason]
        if self.speed_scale < 1:
            parts.append(f"speed capped at {_f(self.speed_scale * 100)} %")
        if self.needs_signature:
            parts.append("needs a signed confirm"
                         + (f" by the {self.role}" if self.role else ""))
        return f"step {self.step} ({self.location}): {self.hazard} — " + "; ".join(parts)

    def as_dict(self) -> dict:
        return {"step": self.step, "hazard": self.hazard, "reason": self.reason,
                "speed_scale": self.speed_scale, "signed": self.needs_signature,
                **({"role": self.role} if self.role else {})}


def classify(step: ResolvedStep, arm: ArmDescription, *, motion: bool,
             closest: tuple[float, str] | None) -> tuple[HazardFinding | None,
                                                         SourceError | None]:
    """The step's class (None: normal) and an error at its ``hazard`` key (a class on a
    step that does not move, or lower than its clearance makes it). ``closest``: the
    move's smallest planned clearance (mm) and what it is to ("guard desk", "wrist to
    desk"), None where none was planned."""
    given = getattr(step.params, "hazard", None)
    if not motion:
        if given is None:
            return None, None
        return None, step.error(f"hazard: a {step.kind} step does not move the arm; the "
                                "hazard class belongs to motion steps (move, move_linear, "
                                "move_velocity, move_trajectory)", "hazard")
    hazard, reason = given or "normal", "given in the step"
    if closest is not None:
        derived = arm.hazards.derived(closest[0])
        if derived is not None and rank(derived[0]) > rank(hazard):
            why = (f"comes within {closest[0]:.1f} mm of {closest[1]}: at least "
                   f"{derived[0]} (the arm file's hazards.{derived[0]}.within_mm is "
                   f"{_f(derived[1])} mm)")
            if given is not None:
                return None, step.error(f"hazard: {given}, but the move {why}", "hazard")
            hazard, reason = derived[0], f"within {closest[0]:.1f} mm of {closest[1]}"
    spec = arm.hazards.spec(hazard)
    if spec is None:
        return None, None
    scale = spec.speed_scale if step.kind in CAPPED_KINDS else 1.0
    role = getattr(spec, "role", None)
    return HazardFinding(step.number, str(step.location), hazard, reason, scale, role), None
