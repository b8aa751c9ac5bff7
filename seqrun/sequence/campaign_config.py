"""The models of a campaign's ``seqrun.toml`` (read by :func:`seqrun.sequence.project.load_config`,
imported only where such a file is read)."""

from __future__ import annotations

import math
import re
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from seqrun.formatting import control_character
from seqrun.shipped import DEFAULT_ARM_NAME


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)

    @field_validator("*", mode="after")
    @classmethod
    def _printable(cls, value: Any) -> Any:
        # a text of seqrun.toml reaches the operator's terminal, as a YAML file's does
        bad = control_character(value) if isinstance(value, str) else None
        if bad is not None:
            raise ValueError(f"a control character ({bad}) in a text: seqrun files hold "
                             "printable text (tabs and line breaks aside)")
        return value


class CampaignSection(_Strict):
    name: str = Field("", description="Name of the campaign, shown in run records.")
    arm: str = Field(DEFAULT_ARM_NAME,
                     description="A shipped arm name (lwa3) or an arm file relative to the "
                                 "campaign folder (arms/my-arm.yaml).")
    on_fault: Literal["halt_all", "halt_faulted"] = Field(
        "halt_all", description="Several arms: halt_all (default) halts every arm when one "
                                "faults; halt_faulted halts only the faulted arm (the others "
                                "finish their steps; the report says so).")


class BusSection(_Strict):
    interface: str | None = Field(None, description="python-can interface (-i); none: the "
                                                    "built-in simulator.")
    channel: str | None = Field(None, description="CAN channel (-c).")
    bitrate: Literal[125000, 250000, 500000, 1000000] | None = Field(
        None, description="Bit rate (-b); default the arm file's.")
    kwargs: dict[str, Any] = Field({}, description="Extra python-can bus arguments.")

    @field_validator("bitrate", mode="before")
    @classmethod
    def _whole_number(cls, value: Any) -> Any:
        # The Literal alone lets 500000.0 through (it compares equal): a bit rate is an
        # integer; a float or a boolean is a typing mistake worth a line.
        if value is not None and type(value) is not int:
            raise ValueError(f"a bit rate is a whole number (125000, 250000, 500000 or "
                             f"1000000), got {value!r}")
        return value


class RunsSection(_Strict):
    dir: Annotated[str, Field(min_length=1)] = Field(
        "runs", description="Run folders, relative to the campaign folder.")


#: An arm id: a letter, then letters, digits, '_' or '-' (``A``, ``chaser-arm``).
ARM_ID_RE = re.compile(r"^[A-Za-z][A-Za-z0-9_-]{0,31}$")


def _finite3(value: list[float], what: str) -> list[float]:
    for v in value:
        if type(v) not in (int, float) or not math.isfinite(v):
            raise ValueError(f"{what} takes three finite numbers, got {v!r}")
    return value


class BasePose(_Strict):
    """Where an arm's base frame stands in the campaign's common facility frame."""

    position_mm: Annotated[list[float], Field(min_length=3, max_length=3)] = Field(
        [0.0, 0.0, 0.0], description="The base frame's origin in the facility frame, mm.")
    rpy_deg: Annotated[list[float], Field(min_length=3, max_length=3)] = Field(
        [0.0, 0.0, 0.0], description="Its orientation: roll, pitch, yaw (degrees, fixed "
                                     "axes x, y, z) of the base frame in the facility frame.")

    @field_validator("position_mm", "rpy_deg", mode="before")
    @classmethod
    def _numbers(cls, value: Any) -> Any:
        # strict mode refuses an int where a float is due: 0 and 0.0 both mean a number here,
        # a boolean does not.
        if isinstance(value, list):
            _finite3(value, "a base pose vector")
            return [float(v) for v in value]
        return value


class ArmSection(_Strict):
    """One arm of a campaign with several (``[arms.A]``)."""

    arm: str = Field(DEFAULT_ARM_NAME, description="A shipped arm name (lwa3) or an arm file "
                                                   "relative to the campaign folder.")
    bus: BusSection = Field(BusSection(), description="This arm's bus (none: a simulated bus "
                                                      "of its own).")
    base: BasePose = Field(BasePose(), description="This arm's base pose in the facility "
                                                   "frame.")


class RosSection(_Strict):
    distribution: Literal["humble", "jazzy", "kilted"] = Field(
        "jazzy", description="The ROS 2 distribution whose message definitions run.mcap is "
                             "written with (docs/ros2.md).")
    mcap: bool = Field(True, description="Write run.mcap (a ROS 2 bag) into every run folder.")


class SimSection(_Strict):
    """The campaign's simulated arm: what the dry run, ``run --virtual-time``, ``run --sim``,
    ``console --sim`` and ``sim serve`` in this campaign all simulate alike."""

    gripper_part_mm: Annotated[float, Field(ge=0)] | None = Field(
        None, description="Width of the part between the simulated gripper's jaws, mm (0: no "
                          "part). Unset: the part the sequence's first grip step names "
                          "(part_width_mm); sim serve and console --sim: no part.")

    @field_validator("gripper_part_mm", mode="before")
    @classmethod
    def _number(cls, value: Any) -> Any:
        # strict refuses 40 where a float is due; a boolean or "40" is a typing mistake
        if type(value) in (int, float):
            if not math.isfinite(value):
                raise ValueError(f"a width is a finite number of mm, got {value!r}")
            return float(value)
        if value is not None:
            raise ValueError(f"a width is a number of mm, got {value!r}")
        return value


class CampaignConfig(_Strict):
    campaign: CampaignSection = CampaignSection()
    bus: BusSection = BusSection()
    runs: RunsSection = RunsSection()
    ros: RosSection = RosSection()
    sim: SimSection = Field(SimSection(), description="The campaign's simulated arm (the "
                                                      "part between the gripper's jaws).")
    arms: dict[str, ArmSection] = Field(
        {}, description="Several arms, by id ([arms.A], [arms.B]): each its arm file, bus and "
                        "base pose. None: the one arm of [campaign] arm and [bus].")

    @field_validator("arms")
    @classmethod
    def _ids(cls, arms: dict[str, ArmSection]) -> dict[str, ArmSection]:
        for name in arms:
            if not ARM_ID_RE.match(name):
                raise ValueError(f"arm id '{name}': a letter, then letters, digits, '_' or "
                                 "'-' (at most 32)")
        return arms

    @model_validator(mode="after")
    def _one_way(self) -> CampaignConfig:
        if self.arms:
            if "arm" in self.campaign.model_fields_set:
                raise ValueError("[campaign] arm and [arms.*] both name arms: with several "
                                 "arms, give each its arm file in its [arms.ID] table")
            if self.bus.model_fields_set:
                raise ValueError("[bus] and [arms.*] both name buses: with several arms, give "
                                 "each its bus in its [arms.ID] table (bus = {...})")
            keys = [_bus_identity(a.bus) for a in self.arms.values()
                    if a.bus.interface is not None]
            if len(keys) != len(set(keys)):
                raise ValueError("two arms name the same bus (interface, channel and "
                                 "kwargs): give each arm a bus of its own")
        return self

    @property
    def arm_ids(self) -> tuple[str, ...]:
        """The arms' ids, in the file's order (empty: the one-arm format)."""
        return tuple(self.arms)


def _bus_identity(bus: BusSection) -> tuple[str, str, str]:
    # the same interface and channel on another host or port (socketcand) is another bus
    return (str(bus.interface), str(bus.channel), repr(sorted(bus.kwargs.items())))
