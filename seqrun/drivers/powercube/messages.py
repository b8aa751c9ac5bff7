"""Fault messages in the operator's units: degrees in user coordinates, joints by name.

The client describes a request as it went on the wire (module radians, e.g.
``SetExtended MIN_POS = -3.141592653589793``); an operator reads joint limits and positions
in user degrees (Totem = zeros). :func:`user_message` rewrites such a request for the arm.
"""

from __future__ import annotations

from seqrun.errors import ModuleTimeoutError


def describe_request(request, arm) -> str | None:
    """``SetExtended MIN_POS (j4) = -120.00°`` for angle-valued writes; None otherwise. The
    request says itself in its joint's units (``in_user_units``: the driver's requests do,
    see :mod:`seqrun.powercube.codec`)."""
    module = getattr(request, "module", None)
    joint = next((j for j in arm.joints if j.module == module), None)
    describe = getattr(request, "in_user_units", None)
    if joint is None or describe is None:
        return None
    return describe(joint)


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
