"""The service layer: the one owner of an arm's bus, under every face (CLI, console, bridges),
and how other processes reach that owner (bus_claim, control_socket).

A face imports :mod:`seqrun.service` and :mod:`seqrun.events`, never the executor, drivers or
the PowerCube client. See :class:`seqrun.service.session.ArmSession`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from seqrun.service.session import (API_VERSION, Activity, ActivityResult, ArmSession,
                                        ArmStatus, JointStatus, RunInfo)

__all__ = ["API_VERSION", "Activity", "ActivityResult", "ArmSession", "ArmStatus",
           "JointStatus", "RunInfo"]


def __getattr__(name: str) -> Any:
    # Loaded on first use: a run (seqrun.service.runner) imports seqrun.service.run_control, and
    # with it this package, without needing the session.
    if name in __all__:
        from seqrun.service import session

        return getattr(session, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
