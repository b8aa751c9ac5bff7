"""The PowerCube driver family: Schunk PRL modules (the LWA 3) over CAN.

:class:`PowerCubeDriver` (:mod:`.driver`) is the :class:`~seqrun.drivers.base.ArmDriver`
the registry opens for an arm whose modules speak PowerCube; beside it, each in its own
module: the setpoint laws (:mod:`.setpoints`), the state words decoded (:mod:`.states`),
Halt/Reset/Home confirmed by reading back (:mod:`.confirm`), the watch for another master's
request frames (:mod:`.foreign`) and fault messages in user units (:mod:`.messages`).
This package and the simulator (``seqrun/sim/``) are the only speakers of
``seqrun.powercube`` (``tests/test_architecture.py``).
"""

from seqrun.drivers.powercube.confirm import (command_and_confirm, confirm_command,
                                              halt_and_confirm)
from seqrun.drivers.powercube.driver import PowerCubeDriver
from seqrun.drivers.powercube.states import joint_state, short_state

__all__ = ["PowerCubeDriver", "command_and_confirm", "confirm_command", "halt_and_confirm",
           "joint_state", "short_state"]
