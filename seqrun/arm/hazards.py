"""Hazard classes of motion steps (normal, caution, hazardous): what the arm file says of
each (a speed cap, the clearance that makes a move one, who signs a hazardous one) and
how a step's class follows from its closest approach. Pure: no I/O."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field

__all__ = ["HAZARD_CLASSES", "HazardClass", "HazardClassSpec", "HazardousClassSpec", "Hazards",
           "rank"]

#: The classes, lowest first.
HAZARD_CLASSES: tuple[str, ...] = ("normal", "caution", "hazardous")
HazardClass = Literal["normal", "caution", "hazardous"]


def rank(hazard: str) -> int:
    """0 normal, 1 caution, 2 hazardous."""
    return HAZARD_CLASSES.index(hazard)


class HazardClassSpec(BaseModel):
    """What class caution means for the motion of a step of that class."""

    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)

    speed_scale: Annotated[float, Field(ge=0.01, le=1, allow_inf_nan=False)] = Field(
        0.5, description="The class's speed cap: a fraction [0.01, 1] of the joints' "
                         "velocity limits; the step's own velocity_scale applies when it is "
                         "smaller (the dry run and the run alike).")
    within_mm: Annotated[float, Field(ge=0, allow_inf_nan=False)] | None = Field(
        None, description="A move whose smallest planned clearance (to a guard, an obstacle, "
                          "another link) is below this is at least of this class (null: the "
                          "class is never derived, only given by a step's hazard key).")


class HazardousClassSpec(HazardClassSpec):
    """What class hazardous means: a lower cap, and a signed confirm before the step."""

    speed_scale: Annotated[float, Field(ge=0.01, le=1, allow_inf_nan=False)] = Field(
        0.25, description="The class's speed cap: a fraction [0.01, 1] of the joints' "
                          "velocity limits; the step's own velocity_scale applies when it "
                          "is smaller (the dry run and the run alike).")
    role: str | None = Field(
        None, min_length=1, max_length=80,
        description="Who signs before such a step starts, e.g. 'test conductor' (null: "
                    "whoever is at the run, by name).")


class Hazards(BaseModel):
    """The arm file's hazard classes (docs/safety.md, "Hazard classes"): a move of class
    caution or hazardous runs at most at its class's speed cap; a hazardous one starts only
    after a signed confirm, which --yes never answers."""

    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)

    caution: HazardClassSpec = Field(
        HazardClassSpec(),
        description="Class caution (default: speed_scale 0.5, never derived).")
    hazardous: HazardousClassSpec = Field(
        HazardousClassSpec(),
        description="Class hazardous (default: speed_scale 0.25, never derived; a signed "
                    "confirm before the step).")

    def spec(self, hazard: str) -> HazardClassSpec | None:
        """The class's settings (None: normal, no cap)."""
        return {"caution": self.caution, "hazardous": self.hazardous}.get(hazard)

    def speed_scale(self, hazard: str) -> float:
        spec = self.spec(hazard)
        return 1.0 if spec is None else spec.speed_scale

    def derived(self, clearance_mm: float) -> tuple[str, float] | None:
        """The class a move that comes within ``clearance_mm`` is at least, with the
        threshold it crossed (None: normal)."""
        for hazard in ("hazardous", "caution"):
            within = self.spec(hazard).within_mm  # type: ignore[union-attr]
            if within is not None and clearance_mm < within:
                return hazard, within
        return None
