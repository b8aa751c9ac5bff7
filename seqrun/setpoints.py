"""Moved to :mod:`seqrun.drivers.setpoints` (the PowerCube driver's setpoint laws)."""

from seqrun.drivers.setpoints import (LAWS, RampSetpoints, SetpointLaw, StepSetpoints,
                                      setpoint_law)

__all__ = ["LAWS", "RampSetpoints", "SetpointLaw", "StepSetpoints", "setpoint_law"]
