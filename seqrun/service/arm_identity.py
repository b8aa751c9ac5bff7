"""The arm's identity, checked before every motion: the modules on the bus are the arm
whose zero was confirmed, and they have not lost power since.

The modules take their encoder zero where they were powered off, so a zero confirmed at
one power-on means nothing after the next one. :func:`check_identity` reads the modules'
serial numbers and their power-session mark (left in their RAM when the zero was
confirmed, :func:`seqrun.service.zero.zero_at_start`) and refuses, in one line, a motion
on other modules or on modules that were power-cycled since: the command that confirmed
the zero is over, and the next one asks again. HOME_OK is never taken as a sign of "not
power-cycled": modules may power on homed, and ``seqrun home`` sets it.

Every motion passes it: the arm session checks it as an activity that moves starts
(runs of one or two arms, console, Foxglove and ROS moves, jogs, home, arm-up), and the
commands that move without a session (``seqrun home``, ``seqrun limits set``) call it
after deciding the zero.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from seqrun.errors import BusError, Refused

if TYPE_CHECKING:
    from seqrun.arm.description import ArmDescription
    from seqrun.drivers.base import ArmDriver
    from seqrun.service.connection import Connection
    from seqrun.service.zero import ZeroInForce


class IdentityRefused(Refused):
    """The modules are not the arm whose zero is in force, or lost power since it was
    confirmed: nothing was sent. One line for the operator."""


def check_identity(driver: ArmDriver, zero: ZeroInForce | None) -> None:
    """Refuse (:class:`IdentityRefused`) a motion unless the modules behind ``driver`` are
    the arm of ``zero`` (its store's serial numbers) and still hold the power-session mark
    left when ``zero`` was confirmed. Reads only.

    ``zero`` None or without a store (the built-in simulator, an arm file that names no
    power-off poses): nothing to check. A zero confirmed on modules that keep no mark
    (``zero.session_mark`` None) is checked by serials only: its command asked the
    operator, and the next command asks again.
    """
    if zero is None or zero.store is None:
        return
    try:
        identity = driver.identity()
        mark = driver.session_mark() if zero.session_mark is not None else None
    except BusError as exc:
        raise IdentityRefused(f"cannot read the arm's identity ({exc}): nothing was "
                              "sent") from None
    if identity != zero.store.identity:
        raise IdentityRefused(f"the modules on the bus ({identity.describe()}) are not the "
                              f"arm whose zero is in force ({zero.store.identity.describe()})"
                              ": nothing was sent")
    if zero.session_mark is not None and mark != zero.session_mark:
        raise IdentityRefused("the modules were powered off since their zero was confirmed "
                              "(their power-session mark is gone): nothing was sent; start "
                              "again and confirm where the arm was powered off")


def open_checked_driver(connection: Connection, arm: ArmDescription, zero: ZeroInForce,
                        response_timeout_s: float | None = None) -> ArmDriver:
    """The driver of ``arm`` at ``zero`` on ``connection``, after :func:`check_identity`
    (for a command that moves without a session: ``seqrun home``, ``seqrun limits set``);
    on a refusal the driver is closed again."""
    from seqrun.drivers.registry import open_driver

    driver = open_driver(zero.apply(arm), connection, response_timeout_s=response_timeout_s)
    try:
        check_identity(driver, zero)
    except BaseException:
        driver.close()
        raise
    return driver
