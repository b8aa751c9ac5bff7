"""Arm drivers: one package per arm protocol behind one interface (:mod:`.base`), found
by name in :mod:`.registry` (``open_driver``).

:mod:`seqrun.drivers.powercube` drives the Schunk PowerCube modules (the LWA 3); the
executor, the session and every command see only :class:`~seqrun.drivers.base.ArmDriver`,
in user degrees.
"""

from __future__ import annotations

from typing import Any

from seqrun.arm.description import ArmDescription
from seqrun.drivers.base import (ArmDriver, ArmPoll, CommandConfirmation, CycleState,
                                 DriverFamily, EventSink, ForeignTraffic, HaltConfirmation,
                                 JointReading, MotionRefused)

__all__ = ["ArmDriver", "ArmPoll", "CommandConfirmation", "CycleState", "DriverFamily",
           "EventSink", "ForeignTraffic", "HaltConfirmation", "JointReading", "MotionRefused",
           "as_driver"]


def as_driver(driver_or_client: Any, arm: ArmDescription) -> ArmDriver:
    """``driver_or_client`` itself if it is an arm driver; a PowerCube client (what the
    executor was given before drivers existed) is wrapped in a PowerCube driver."""
    if isinstance(driver_or_client, ArmDriver):
        return driver_or_client
    from seqrun.drivers.powercube import PowerCubeDriver

    return PowerCubeDriver(driver_or_client, arm)
