"""``seqrun status`` and ``seqrun halt`` next to a controller that holds the bus.

One controller per bus (seqrun/service/bus_claim.py): while a run holds a shared bus,
``status`` asks it over its control socket instead of asking the modules (a second
master's questions cannot be told from the run's); ``halt`` sends the Halt broadcast
straight to the bus (a broadcast needs no answer: always safe) and then asks the owner to
confirm. When nobody holds the bus they read it themselves, claiming it for each reading
(a watch never keeps a run from starting: a run waits for such a short claim).
"""

from __future__ import annotations

from typing import Any, Callable

from seqrun.errors import SeqrunError

Warn = Callable[[str], None]


class OwnerDidNotAnswer(SeqrunError):
    """The process that holds the bus did not answer a status request."""


def owner_text(holder: dict) -> str:
    """``the running seqrun (pid 1234: seqrun run opsafe.yaml)``."""
    return f"the running seqrun (pid {holder['pid']}: {holder['command']})"


class StatusSource:
    """Where ``seqrun status`` gets a reading: the bus owner, else the bus itself.

    :param open_bus: opens ``(connection, driver)`` without claiming (the claim is taken
        per reading here).
    :param key: the bus's claim key (None: the simulator of this process).
    """

    def __init__(self, arm, key: tuple[str, str] | None,
                 open_bus: Callable[[], tuple], warn: Warn) -> None:
        self.arm = arm
        self.key = key
        self.open_bus = open_bus
        self.warn = warn
        self.connection: Any = None
        self.driver: Any = None
        self.zero_text: str | None = None
        self._arm_read = arm
        self._foreign: list = []
        #: The owner's record when the last reading came from it, else None.
        self.holder: dict | None = None

    def read(self, previous: dict | None = None, *, tolerate_loss: bool = False) -> dict:
        """One reading (the shape of :func:`seqrun.service.arm_access.read_status`).

        :raises ~seqrun.errors.BusError: a bus reading failed (without ``tolerate_loss``).
        :raises OwnerDidNotAnswer: the bus owner's socket gave no status.
        :raises ~seqrun.errors.Refused: the bus is held by a controller that serves no
            socket.
        """
        if self.key is not None:
            from seqrun.service.control_socket import ask_owner

            reply = ask_owner(*self.key, "status")
            if reply is not None:
                self._close_bus()   # the run's frames must not queue up here meanwhile
                self.holder = reply["holder"]
                if not reply.get("ok"):
                    raise OwnerDidNotAnswer(f"{owner_text(self.holder)} did not answer: "
                                            f"{reply.get('error')}")
                return reply["status"]
        self.holder = None
        return self._read_bus(previous, tolerate_loss)

    def _read_bus(self, previous: dict | None, tolerate_loss: bool) -> dict:
        from seqrun.service.arm_access import read_status

        claim = None
        if self.key is not None:
            from seqrun.service.bus_claim import claim_bus

            claim = claim_bus(*self.key, transient=True)
        try:
            if self.connection is None:
                self._open()
            elif claim is not None:
                self._drain()
            status = read_status(self.driver, self._arm_read, previous,
                                 tolerate_loss=tolerate_loss)
        finally:
            if claim is not None:
                claim.release()
        if self._foreign:
            first, more = self._foreign[0], len(self._foreign) - 1
            self._foreign.clear()
            self.warn(f"{first.message()}" + (f" (+{more} more frames)" if more else "")
                      + ": its questions and ours cannot be told apart")
        return status

    def _open(self) -> None:
        from seqrun.cli.zero import zero_for_reading

        self.connection, self.driver = self.open_bus()
        self.driver.watch_foreign(self._foreign.append)
        self._arm_read, text = zero_for_reading(self.connection, self.arm)
        self.driver.use_arm(self._arm_read)  # positions in the zero reference in force
        if self.zero_text is None:
            self.zero_text = text

    def _drain(self) -> None:
        """Frames that came while this process did not hold the bus (another controller's,
        claimed) are not ours to judge."""
        for _ in range(10_000):
            if self.connection.bus.recv(0.0) is None:
                return

    @property
    def description(self) -> str | None:
        return None if self.connection is None else self.connection.description

    def _close_bus(self) -> None:
        if self.connection is not None:
            self.driver.close()
            self.connection.close()
            self.connection = self.driver = None

    def close(self) -> None:
        self._close_bus()


def warn_once_in(seconds: float, write: Warn) -> Warn:
    """``write`` each distinct line at most once per ``seconds`` (a watch repeats)."""
    import time

    last: dict[str, float] = {}

    def warn(text: str) -> None:
        now = time.monotonic()
        if now - last.get(text, -seconds) >= seconds:
            last[text] = now
            write(text)
    return warn
