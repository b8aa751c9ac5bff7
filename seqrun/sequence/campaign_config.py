"""The models of a campaign's ``seqrun.toml`` (read by :func:`seqrun.sequence.project.load_config`,
imported only where such a file is read)."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

from seqrun.shipped import DEFAULT_ARM_NAME


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)


class CampaignSection(_Strict):
    name: str = Field("", description="Name of the campaign, shown in run records.")
    arm: str = Field(DEFAULT_ARM_NAME,
                     description="A shipped arm name (lwa3) or an arm file relative to the "
                                 "campaign folder (arms/my-arm.yaml).")


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


class RosSection(_Strict):
    distribution: Literal["humble", "jazzy", "kilted"] = Field(
        "jazzy", description="The ROS 2 distribution whose message definitions run.mcap is "
                             "written with (docs/ros2.md).")
    mcap: bool = Field(True, description="Write run.mcap (a ROS 2 bag) into every run folder.")


class CampaignConfig(_Strict):
    campaign: CampaignSection = CampaignSection()
    bus: BusSection = BusSection()
    runs: RunsSection = RunsSection()
    ros: RosSection = RosSection()
