"""Arm drivers by name, found the way python-can finds its interfaces.

:data:`DRIVERS` maps a driver's name (an arm file's ``driver``) to ``"module:Class"``; the
module is imported only when an arm of that family is opened, so a family's dependencies
cost nothing to the others. :func:`open_driver` is the one way the service layer gets an
:class:`~seqrun.drivers.base.ArmDriver`: a run, a dry run, the session, ``seqrun status``.
What a report needs of a family without an arm on the bus (the words of a logged state
code) is asked of the class (:func:`cycle_state`). Adding a family is one package under
``seqrun/drivers/`` and one line here (docs/adding-a-driver.md).
"""

from __future__ import annotations

from collections.abc import Mapping
from importlib import import_module
from typing import TYPE_CHECKING, Any

from seqrun.errors import UserInputError

if TYPE_CHECKING:
    from seqrun.arm.description import ArmDescription
    from seqrun.drivers.base import ArmDriver, CycleState, DriverFamily

#: The driver of an arm file that names none.
DEFAULT_DRIVER = "powercube"

#: Every driver family: name -> "module:Class" (imported on first use).
DRIVERS: dict[str, str] = {
    "powercube": "seqrun.drivers.powercube:PowerCubeDriver",
}

__all__ = ["DEFAULT_DRIVER", "DRIVERS", "cycle_state", "driver_class", "driver_name",
           "open_driver", "simulator_positions"]


def driver_name(arm: ArmDescription | None) -> str:
    """The driver ``arm`` names (its ``driver``), else :data:`DEFAULT_DRIVER`."""
    return getattr(arm, "driver", None) or DEFAULT_DRIVER


def driver_class(name: str) -> type[DriverFamily]:
    """The class registered as ``name``; an unknown name is one line naming the known."""
    try:
        module, _, attribute = DRIVERS[name].partition(":")
    except KeyError:
        raise UserInputError(f"unknown arm driver '{name}' (known: "
                             f"{', '.join(sorted(DRIVERS))})") from None
    return getattr(import_module(module), attribute)


def open_driver(arm: ArmDescription, connection: Any, *,
                response_timeout_s: float | None = None) -> ArmDriver:
    """The driver of ``arm`` (its family by :func:`driver_name`) on an open connection.
    ``response_timeout_s``: how long to wait for a drive's answer (default: the arm
    file's). The connection stays the caller's to close."""
    return driver_class(driver_name(arm)).open(arm, connection,
                                               response_timeout_s=response_timeout_s)


def cycle_state(arm: ArmDescription | None, code: int) -> CycleState:
    """A per-cycle state code as ``arm``'s driver logged it (events' ``state``), back as
    the state it was: ``describe()`` gives the drive's own flag names."""
    return driver_class(driver_name(arm)).cycle_state(code)


def simulator_positions(arm: ArmDescription,
                        joints_deg: Mapping[str, float]) -> dict[int, float]:
    """What ``arm``'s simulated drives read (module id -> their units) while the arm
    stands at ``joints_deg`` (user degrees): where a dry run starts them."""
    return driver_class(driver_name(arm)).simulator_positions(arm, joints_deg)
