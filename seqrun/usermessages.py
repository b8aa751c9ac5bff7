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

#: Parameters holding a joint position (module radians; user = module - offset).
_POSITIONS = {ParamId.MIN_POS, ParamId.MAX_POS, ParamId.ACT_POS, ParamId.DEF_MIN_POS,
              ParamId.DEF_MAX_POS}
#: Parameters holding a rate (rad/s, rad/s²): no offset.
_RATES = {ParamId.MAX_VEL: "°/s", ParamId.MAX_ACC: "°/s²", ParamId.ACT_VEL: "°/s",
          ParamId.DEF_MAX_VEL: "°/s", ParamId.DEF_MAX_ACC: "°/s²"}
_POSITION_MODES = {MotionMode.FRAMP, MotionMode.FRAMP_ACK, MotionMode.FSTEP,
                   MotionMode.FSTEP_ACK}
_VELOCITY_MODES = {MotionMode.FVEL, MotionMode.FVEL_ACK}


def describe_request(request, arm) -> str | None:
    """``SetExtended MIN_POS (j4) = -120.00°`` for angle-valued writes; None otherwise."""
    module = getattr(request, "module", None)
    joint = next((j for j in arm.joints if j.module == module), None)
    if joint is None:
        return None
    if isinstance(request, SetParam):
        param = ParamId(request.param)
        if param in _POSITIONS:
            value = f"{_deg(joint.to_user_deg(float(request.value)))}°"
        elif param in _RATES:
            value = f"{_deg(math.degrees(float(request.value)))} {_RATES[param]}"
        else:
            return None
        return f"SetExtended {param.name} ({joint.name}) = {value}"
    if isinstance(request, SetMotion):
        mode = MotionMode(request.mode)
        if mode in _POSITION_MODES:
            value = f"{_deg(joint.to_user_deg(float(request.value)))}°"
        elif mode in _VELOCITY_MODES:
            value = f"{_deg(math.degrees(float(request.value)))} °/s"
        else:
            return None
        timing = f" in {request.time_ms} ms" if request.time_ms is not None else ""
        return f"SetMotion {mode.name} ({joint.name}) {value}{timing}"
    return None


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
