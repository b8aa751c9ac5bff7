"""Request bodies and live messages of the console's API, strictly typed.

Strict (pydantic strict mode): a number is a JSON number (``true`` is not 1, ``"12"`` is not
12), a boolean is ``true`` or ``false`` (never 0 or 1), a text is a JSON string; unknown keys,
NaN and infinity are refused. Duplicate keys are refused before a model sees the body
(:mod:`seqrun.console.bodies`).
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field

Finite = Annotated[float, Field(allow_inf_nan=False)]
#: A live message's ``id``, echoed in its reply.
MessageId = Annotated[str, Field(max_length=64)] | Annotated[int, Field(ge=0, le=2**53)] | None


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)


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
    mode: Literal["position", "velocity"] = Field(
        "position", description="position: FRAMP setpoints; velocity: FVEL (the thesis "
                                "GUI's jog) with the modules' watchdog armed.")


class GripBody(_Strict):
    part_width_mm: Annotated[float, Field(gt=0, allow_inf_nan=False)]
    force_n: Annotated[float, Field(gt=0, allow_inf_nan=False)]


class ReleaseBody(_Strict):
    width_mm: Annotated[float, Field(gt=0, allow_inf_nan=False)]


class RunBody(_Strict):
    sequence: str = Field(min_length=1, max_length=400,
                          description="A sequence name as listed by GET /sequences.")
    speed: Annotated[float, Field(gt=0, le=1, allow_inf_nan=False)] = 1.0
    step_mode: bool = False
    first_step: Annotated[int, Field(ge=1)] = 1


class ArmsRunBody(_Strict):
    """A sequence of several arms run from the console of several arms."""

    sequence: str = Field(min_length=1, max_length=400,
                          description="A sequence name as listed by GET /sequences.")
    speed: Annotated[float, Field(gt=0, le=1, allow_inf_nan=False)] = 1.0


class AnswerBody(_Strict):
    question_id: str = Field(min_length=1, max_length=40)
    yes: bool
    #: Who answers a signed question yes (required there, asked again while empty).
    name: str | None = Field(None, max_length=80)
    #: A yes to a question with choices (its confirm_requested lists them) names one.
    choice: str | None = Field(None, min_length=1, max_length=40)


class SavePoseBody(_Strict):
    name: str = Field(min_length=1, max_length=100)
    overwrite: bool = False


class TakeControlBody(_Strict):
    name: str = Field("API client", min_length=1, max_length=60,
                      description="Who takes control, as the others see it.")
    take_over: bool = Field(False, description="Take control from the client that holds "
                                               "it: its motion is stopped first, it is told.")


# -- live WebSocket messages (page -> server) ----------------------------------------------
class HaltMessage(_Strict):
    op: Literal["halt"]
    id: MessageId = None
    reason: str = Field("STOP (console)", max_length=200)


#: A control secret (seqrun/service/control.py), where a live message may carry one.
Secret = Annotated[str, Field(min_length=1, max_length=100)] | None
#: Which arm a live message addresses (a console of several arms; one arm: none).
ArmId = Annotated[str, Field(min_length=1, max_length=40)] | None


class JogMessage(_Strict):
    op: Literal["jog"]
    id: MessageId = None
    arm: ArmId = None
    joint: str = Field(min_length=1, max_length=40)
    speed_scale: Annotated[float, Field(ge=-1, le=1, allow_inf_nan=False)]
    mode: Literal["position", "velocity"] = "position"
    #: The control secret; left out: the one this connection got when it took control.
    token: Secret = None


class JogStopMessage(_Strict):
    op: Literal["jog_stop"]
    id: MessageId = None
    #: None in a console of several arms: every arm's jog ends.
    arm: ArmId = None


class TakeControlMessage(_Strict):
    """This page takes control (the reply carries its secret, for this page alone)."""

    op: Literal["take_control"]
    id: MessageId = None
    take_over: bool = False


class ReleaseControlMessage(_Strict):
    op: Literal["release_control"]
    id: MessageId = None


class PingMessage(_Strict):
    op: Literal["ping"]
    id: MessageId = None


LIVE_MESSAGES: dict[str, type[_Strict]] = {
    "halt": HaltMessage, "jog": JogMessage, "jog_stop": JogStopMessage, "ping": PingMessage,
    "take_control": TakeControlMessage, "release_control": ReleaseControlMessage}
