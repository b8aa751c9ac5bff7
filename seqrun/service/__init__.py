"""The service layer: the one owner of an arm's bus, under every face (CLI, console, bridges),
and how other processes reach that owner (bus_claim, control_socket).

A face imports :mod:`seqrun.service` and :mod:`seqrun.events`, never the executor, drivers or
the PowerCube client. See :class:`seqrun.service.session.ArmSession`.
"""

from seqrun.service.session import (API_VERSION, Activity, ActivityResult, ArmSession,
                                    ArmStatus, JointStatus, RunInfo)

__all__ = ["API_VERSION", "Activity", "ActivityResult", "ArmSession", "ArmStatus",
           "JointStatus", "RunInfo"]
