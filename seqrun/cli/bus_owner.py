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


def live_targets(context, what: str, pid: int | None = None) -> list | None:
    """The live seqrun runs/consoles a command with no bus acts through (None: the command
    acts on its bus as resolved). ``what``: "status", "halt", "reset" or "home".

    With no bus configured a command never acts on a private simulator of its own: it acts
    through the live runs and consoles of *this* arm (started in this campaign, as this arm
    id; ``status``: exactly one, or ``--pid``). Another folder's run or console is never
    acted on nor reported on. With none of this arm live there is no arm
    (:class:`~seqrun.service.arm_context.NoArm`, exit 2), and where another seqrun drives a
    real bus on this machine the message lists it with the command that reaches it: an
    operator's halt never silently misses an arm in motion. ``--pid`` picks any live run or
    console by its pid (of one driving several arms: this arm's record). ``--sim`` (a
    private simulator asked for) is refused for ``halt`` beside a live run or console of
    this arm, or one on a real bus: its "confirmed" would be about the wrong arm.
    """
    from seqrun.errors import UserInputError
    from seqrun.service.arm_context import NoArm

    bus = context.bus
    if bus.force_sim:
        live = _meant(context) if what == "halt" else []
        if live:
            raise UserInputError(f"--sim halts a private simulator, not the arm "
                                 f"{_names(live)} drives on this machine: leave out --sim "
                                 "to halt it")
        return None
    if not bus.defaulted_to_simulator:
        if pid is not None:
            raise UserInputError("--pid applies when no bus is given")
        return None
    everyone = context.live_controllers()
    if pid is not None:
        live = [h for h in everyone if h.pid == pid]
        if not live:
            raise UserInputError(f"no live seqrun run or console with pid {pid} on this "
                                 "machine")
        # A run or console of several arms holds one record per arm: this arm's is meant.
        live = context.own_controllers(live) or live
    else:
        live = context.own_controllers(everyone)
    if not live:
        doing = {"status": "read"}.get(what, what)
        real = [h for h in everyone if h.reach]
        arm = f"arm {context.arm_id} of " if context.arm_id else ""
        if real:
            raise NoArm(f"no arm to {doing} in {arm}{context.project.describe()}: no bus "
                        "configured, and none of its runs or consoles is live on this "
                        f"machine; another seqrun drives a real bus here ({doing} it with "
                        "the command after it):\n"
                        + "\n".join(reach_line(h, what) for h in real))
        raise NoArm(f"no arm to {doing}: no bus configured (no -i/-c, no [bus] in a "
                    f"seqrun.toml, no python-can configuration) and no seqrun run or console "
                    f"of {arm}{context.project.describe()} is live on this machine; name "
                    "the bus with -i/-c, or give --sim for a private simulator")
    if what == "reset":
        raise UserInputError(f"no bus configured, and {_names(live)} live on this machine: "
                             "reset the arm through it (the console's Reset, the run's "
                             "sequence), or name its bus with -i/-c")
    if what == "home":
        raise UserInputError(f"no bus configured, and {_names(live)} live on this machine: "
                             "home the arm through it (the console's Home, the run's "
                             "sequence), or name its bus with -i/-c")
    if what == "status" and len(live) > 1:
        raise UserInputError(f"{_names(live)} live on this machine: pick one with --pid PID")
    return live


def _meant(context) -> list:
    """The live runs/consoles an operator may mean by "the arm": this arm's, and any on a
    real bus (another process's built-in simulator is nobody's arm)."""
    return [h for h in context.live_controllers()
            if h.reach or context.own_controllers([h])]


def reach_line(holder, what: str) -> str:
    """``  seqrun pid 4711 (seqrun run totem.yaml) on socketcand:127.0.0.1:29536/can0:
    seqrun halt -i socketcand -c can0 --bus-kwargs host=127.0.0.1 port=29536``."""
    import shlex

    from seqrun.formatting import terminal_text

    verb = what if what in ("status", "halt", "reset", "home") else "halt"
    return (f"  seqrun pid {holder.pid} ({terminal_text(holder.command)}) on "
            f"{terminal_text(holder.bus)}: {shlex.join(['seqrun', verb, *holder.reach])}")


def _names(holders) -> str:
    from seqrun.formatting import terminal_text

    names = [f"seqrun pid {h.pid} ({terminal_text(h.command)})" for h in holders]
    return names[0] + " is" if len(names) == 1 else ", ".join(names) + " are"


def holder_bus(holder) -> str:
    """The bus a live holder drives, for the operator."""
    from seqrun.service.arm_context import SIMULATOR_CLAIM_INTERFACE

    if not holder.bus or holder.bus.startswith(SIMULATOR_CLAIM_INTERFACE + ":"):
        return "its built-in simulator"
    return holder.bus


class StatusSource:
    """Where ``seqrun status`` gets a reading: the bus owner, else the bus itself.

    :param open_bus: opens ``(connection, driver)`` without claiming (the claim is taken
        per reading here).
    :param key: the bus's claim key (None: the simulator of this process).
    """

    def __init__(self, arm, key: tuple[str, str] | None,
                 open_bus: Callable[[], tuple], warn: Warn, *, live: Any = None) -> None:
        self.arm = arm
        self.key = key
        #: A live run or console found with no bus given: every reading comes from it.
        self.live = live
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
        from seqrun.service.control_socket import ask_holder, ask_owner

        reply = None
        if self.live is not None:
            reply = ask_holder(self.live, "status")
            if reply is None:
                raise OwnerDidNotAnswer(f"seqrun pid {self.live.pid} ({self.live.command}) "
                                        "has ended")
        elif self.key is not None:
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
