"""Fault messages in the operator's units: degrees in user coordinates, joints by name.

The client describes a request as it went on the wire (module radians, e.g.
``SetExtended MIN_POS = -3.141592653589793``); an operator reads joint limits and positions
in user degrees (Totem = zeros). :func:`user_message` rewrites such a request for the arm,
converting with :mod:`.units` (positions get the joint's offset, rates only the unit).
"""

from __future__ import annotations

import math

from seqrun.arm.description import ArmDescription
from seqrun.drivers.powercube.units import ModuleUnits
from seqrun.errors import ModuleTimeoutError
from seqrun.powercube.codec import SetMotion, SetParam
from seqrun.powercube.protocol import MotionMode, ParamId

#: The unit each angle-valued parameter is written in: a position ("°": module radians,
#: user = module - offset) or a rate (rad/s, rad/s²: no offset).
PARAM_UNITS = {ParamId.MIN_POS: "°", ParamId.MAX_POS: "°", ParamId.ACT_POS: "°",
               ParamId.DEF_MIN_POS: "°", ParamId.DEF_MAX_POS: "°",
               ParamId.MAX_VEL: "°/s", ParamId.MAX_ACC: "°/s²", ParamId.ACT_VEL: "°/s",
               ParamId.DEF_MAX_VEL: "°/s", ParamId.DEF_MAX_ACC: "°/s²"}
#: Likewise for the motion modes: a target position or a velocity.
MODE_UNITS = {MotionMode.FRAMP: "°", MotionMode.FRAMP_ACK: "°", MotionMode.FSTEP: "°",
              MotionMode.FSTEP_ACK: "°", MotionMode.FVEL: "°/s", MotionMode.FVEL_ACK: "°/s"}


def describe_request(request, arm: ArmDescription) -> str | None:
    """``SetExtended MIN_POS (j4) = -120.00°`` / ``SetMotion FRAMP_ACK (j2) 45.00°`` for an
    angle-valued write to one of ``arm``'s modules; None otherwise."""
    module = getattr(request, "module", None)
    joint = next((j for j in arm.joints if j.module == module), None)
    if joint is None:
        return None
    if isinstance(request, SetParam):
        param = ParamId(request.param)
        prefix, unit, suffix = (f"SetExtended {param.name} ({joint.name}) = ",
                                PARAM_UNITS.get(param), "")
    elif isinstance(request, SetMotion):
        mode = MotionMode(request.mode)
        prefix, unit = f"SetMotion {mode.name} ({joint.name}) ", MODE_UNITS.get(mode)
        suffix = f" in {request.time_ms} ms" if request.time_ms is not None else ""
    else:
        return None
    if unit is None:
        return None
    value = float(request.value)
    user = (ModuleUnits(arm).joint_user_deg(joint.module, value) if unit == "°"
            else math.degrees(value))
    text = f"{round(user, 2) + 0.0:.2f}"  # two decimals, never -0.00
    return f"{prefix}{text}{'°' if unit == '°' else ' ' + unit}{suffix}"


def user_message(exc: BaseException, arm: ArmDescription) -> str:
    """``str(exc)``, with a timed-out request described in user degrees where it has one."""
    if isinstance(exc, ModuleTimeoutError) and exc.request is not None:
        described = describe_request(exc.request, arm)
        if described is not None:
            others = exc.what.partition(" (modules ")
            rest = f" (modules {others[2]}" if others[1] else ""
            return (f"module {exc.module}: no acknowledge to {described}{rest} within "
                    f"{exc.timeout * 1000:.0f} ms")
    return str(exc)
