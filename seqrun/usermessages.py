"""Fault messages in the operator's units: degrees in user coordinates, joints by name.

The client describes a request as it went on the wire (module radians, e.g.
``SetExtended MIN_POS = -3.141592653589793``); an operator reads joint limits and positions
in user degrees (Totem = zeros). :func:`user_message` rewrites such a request for the arm.
"""

from __future__ import annotations

import math

from seqrun.errors import ModuleTimeoutError
from seqrun.powercube.codec import SetMotion, SetParam
from seqrun.powercube.protocol import MotionMode, ParamId

#: The unit each angle-valued parameter is written in: a position ("°": module radians,
#: user = module - offset) or a rate (rad/s, rad/s²: no offset).
_PARAM_UNITS = {ParamId.MIN_POS: "°", ParamId.MAX_POS: "°", ParamId.ACT_POS: "°",
                ParamId.DEF_MIN_POS: "°", ParamId.DEF_MAX_POS: "°",
                ParamId.MAX_VEL: "°/s", ParamId.MAX_ACC: "°/s²", ParamId.ACT_VEL: "°/s",
                ParamId.DEF_MAX_VEL: "°/s", ParamId.DEF_MAX_ACC: "°/s²"}
#: Likewise for the motion modes: a target position or a velocity.
_MODE_UNITS = {MotionMode.FRAMP: "°", MotionMode.FRAMP_ACK: "°", MotionMode.FSTEP: "°",
               MotionMode.FSTEP_ACK: "°", MotionMode.FVEL: "°/s", MotionMode.FVEL_ACK: "°/s"}


def describe_request(request, arm) -> str | None:
    """``SetExtended MIN_POS (j4) = -120.00°`` for angle-valued writes; None otherwise."""
    module = getattr(request, "module", None)
    joint = next((j for j in arm.joints if j.module == module), None)
    if joint is None:
        return None
    if isinstance(request, SetParam):
        param = ParamId(request.param)
        unit = _PARAM_UNITS.get(param)
        if unit is None:
            return None
        return (f"SetExtended {param.name} ({joint.name}) = "
                f"{_user_value(joint, request.value, unit)}")
    if isinstance(request, SetMotion):
        mode = MotionMode(request.mode)
        unit = _MODE_UNITS.get(mode)
        if unit is None:
            return None
        timing = f" in {request.time_ms} ms" if request.time_ms is not None else ""
        return (f"SetMotion {mode.name} ({joint.name}) "
                f"{_user_value(joint, request.value, unit)}{timing}")
    return None


def _user_value(joint, value, unit: str) -> str:
    """A module value in the operator's units: a position ("°") in user degrees of
    ``joint``, a rate converted from radians alone."""
    if unit == "°":
        return f"{_deg(joint.to_user_deg(float(value)))}°"
    return f"{_deg(math.degrees(float(value)))} {unit}"


def user_message(exc: BaseException, arm) -> str:
    """``str(exc)``, with a timed-out request described in user degrees where it has one."""
    if isinstance(exc, ModuleTimeoutError) and exc.request is not None:
        described = describe_request(exc.request, arm)
        if described is not None:
            others = exc.what.partition(" (modules ")
            rest = f" (modules {others[2]}" if others[1] else ""
            return (f"module {exc.module}: no acknowledge to {described}{rest} within "
                    f"{exc.timeout * 1000:.0f} ms")
    return str(exc)


def _deg(value: float) -> str:
    value = round(value, 2)
    return f"{value + 0.0:.2f}"  # never -0.00
