"""Request bodies of the console's API: strict (unknown keys, NaN and infinity refused)."""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field

Finite = Annotated[float, Field(allow_inf_nan=False)]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class HaltBody(_Strict):
    reason: str = Field("STOP (console)", max_length=200)


class PoseMove(_Strict):
    name: str = Field(min_length=1, max_length=100, description="A pose name (GET /poses).")
    velocity_scale: Annotated[float, Field(gt=0, le=1, allow_inf_nan=False)] | None = None


class JointMap(_Strict):
    joints: dict[str, Finite] = Field(min_length=1, description="Joint name -> value.")


class JogBody(_Strict):
    joint: str = Field(min_length=1, max_length=40)
    speed_scale: Annotated[float, Field(ge=-1, le=1, allow_inf_nan=False)]


class RunBody(_Strict):
    sequence: str = Field(min_length=1, max_length=400,
                          description="A sequence name as listed by GET /sequences.")
    speed: Annotated[float, Field(gt=0, le=1, allow_inf_nan=False)] = 1.0
    step_mode: bool = False
    first_step: Annotated[int, Field(ge=1)] = 1


class AnswerBody(_Strict):
    question_id: str | int
    yes: bool


class SavePoseBody(_Strict):
    name: str = Field(min_length=1, max_length=100)
    overwrite: bool = False
