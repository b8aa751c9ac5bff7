"""One controller per bus: a lock per (interface, channel) that a second seqrun controller
finds taken, and a record naming who holds it.

The PowerCube protocol has no sequence numbers: two masters asking the modules the same
questions cannot tell their answers apart. So every seqrun process that talks to a shared
bus (a real adapter, or ``seqrun sim serve``'s socketcand endpoint) claims it first; a
second one is refused with one line naming the holder (pid, command, since when).

How: a per-user runtime directory (``$XDG_RUNTIME_DIR/seqrun``, else
``/tmp/seqrun-$UID``, mode 0700) holds, per bus, a lock file held with ``fcntl.flock``
(the kernel releases it when the holder dies, however it dies: no stale claims) and a JSON
holder record beside it (pid, argv, since, the control socket's path), written after the
lock is taken and removed before it is released. The lock is the truth; the record only
names the holder.

A *transient* claim (``status``, ``halt``, ``reset``: a command done within a second or
two) makes a second claimer wait for it briefly instead of being refused, so a watch that
claims the bus for each refresh never keeps a run from starting.

Claims are per user: two users on one machine do not see each other's claims.

A record also says which arm its holder drives, for ``seqrun halt`` and ``seqrun status``
with no bus (seqrun/cli/bus_owner.py): the campaign folder and arm id, the options that
reach its bus (``-i … -c … --bus-kwargs …``), and the holder's process start time, so that
a record left by a killed process whose pid was reused is not taken for a live holder.
"""

from __future__ import annotations

import errno
import fcntl
import hashlib
import json
import os
import re
import shlex
import stat
import sys
import tempfile
import time
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Callable

from seqrun.errors import Refused, UserInputError

#: Overrides the runtime directory (tests, several seqrun installations side by side).
RUNTIME_DIR_ENV = "SEQRUN_RUNTIME_DIR"
#: How long a claimer waits for a transient holder before it is refused, s.
TRANSIENT_WAIT_S = 3.0
_POLL_S = 0.02


def runtime_dir() -> Path:
    """``$SEQRUN_RUNTIME_DIR``, else ``$XDG_RUNTIME_DIR/seqrun``, else ``/tmp/seqrun-$UID``."""
    explicit = os.environ.get(RUNTIME_DIR_ENV, "").strip()
    if explicit:
        return Path(explicit)
    xdg = os.environ.get("XDG_RUNTIME_DIR", "").strip()
    if xdg and Path(xdg).is_dir():
        return Path(xdg) / "seqrun"
    return Path(tempfile.gettempdir()) / f"seqrun-{os.getuid()}"


def _private_dir(path: Path) -> Path:
    """Create ``path`` (0700) or check that an existing one is ours and not a link: in /tmp
    another user could have made it first."""
    try:
        path.mkdir(mode=0o700, parents=True, exist_ok=True)
        st = os.lstat(path)
    except OSError as exc:
        raise UserInputError(f"cannot use the runtime directory {path}: "
                             f"{exc.strerror or exc}") from None
    if not stat.S_ISDIR(st.st_mode) or st.st_uid != os.getuid():
        raise UserInputError(f"the runtime directory {path} is not a directory of this user; "
                             f"remove it or set {RUNTIME_DIR_ENV}")
    return path


def bus_name(interface: str, channel: str) -> str:
    """How a bus is named to the operator: ``socketcan:can0``."""
    return f"{interface}:{channel}"


def _file_stem(interface: str, channel: str) -> str:
    readable = re.sub(r"[^A-Za-z0-9_.-]+", "_", f"{interface}-{channel}")[:40]
    digest = hashlib.sha1(f"{interface}\0{channel}".encode()).hexdigest()[:10]
    return f"{readable}-{digest}"


def command_line(argv: list[str] | None = None) -> str:
    """The command as the operator typed it: ``seqrun run totem.yaml`` (also when started
    as ``python -m seqrun``)."""
    args = list(sys.argv if argv is None else argv)
    return shlex.join(["seqrun", *args[1:]])


@dataclass(frozen=True)
class Holder:
    """Who holds a bus, from its record."""

    pid: int
    command: str
    since: float                     # epoch seconds
    argv: tuple[str, ...] = ()
    socket: str | None = None        # the control socket's path, when it serves one
    transient: bool = False
    bus: str = ""                    # the bus's name (bus_name), for a list of holders
    #: The holder's process start time (clock ticks since boot, /proc/PID/stat); None
    #: where the system does not say (then only the pid is checked).
    started: int | None = None
    campaign: str | None = None      # the campaign folder (resolved) of the arm it drives
    arm_id: str | None = None        # its id in a campaign of several arms
    #: The command-line options that reach its bus from another terminal (empty: a bus
    #: of its process only, the built-in simulator).
    reach: tuple[str, ...] = ()
    #: The serial numbers of the modules it drives (ArmIdentity.key), once read.
    serials: str = ""

    def describe(self) -> str:
        """``pid 1234 (seqrun run totem.yaml) since 14:02:11``."""
        when = datetime.fromtimestamp(self.since).strftime("%H:%M:%S")
        return f"pid {self.pid} ({self.command}) since {when}"

    def as_dict(self) -> dict:
        return {"pid": self.pid, "command": self.command, "since": self.since,
                "argv": list(self.argv), "socket": self.socket, "transient": self.transient,
                "bus": self.bus, "started": self.started, "campaign": self.campaign,
                "arm_id": self.arm_id, "reach": list(self.reach), "serials": self.serials}

    @classmethod
    def from_dict(cls, data: dict) -> Holder:
        return cls(pid=int(data["pid"]), command=str(data.get("command", "?")),
                   since=float(data.get("since", 0.0)), argv=tuple(data.get("argv") or ()),
                   socket=data.get("socket"), transient=bool(data.get("transient", False)),
                   bus=str(data.get("bus") or ""),
                   started=None if data.get("started") is None else int(data["started"]),
                   campaign=data.get("campaign"), arm_id=data.get("arm_id"),
                   reach=tuple(str(w) for w in data.get("reach") or ()),
                   serials=str(data.get("serials") or ""))

    def alive(self) -> bool:
        """Its process still runs: the pid exists and, where the record has it, started
        when the holder did (a pid the system gave to another process is not alive)."""
        if not pid_alive(self.pid):
            return False
        return self.started is None or process_start(self.pid) in (None, self.started)


def pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def process_start(pid: int) -> int | None:
    """When process ``pid`` started, in clock ticks since boot (field 22 of
    /proc/PID/stat); None where there is no /proc or no such process."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    # the command name (field 2) may hold spaces and parentheses: count after the last ')'
    fields = text.rpartition(")")[2].split()
    try:
        return int(fields[19])
    except (IndexError, ValueError):
        return None


def read_holder(interface: str, channel: str, *, directory: Path | None = None
                ) -> Holder | None:
    """The record of whoever holds the bus now, or None (free, or no readable record)."""
    path = (directory or runtime_dir()) / f"{_file_stem(interface, channel)}.json"
    try:
        return Holder.from_dict(json.loads(path.read_text()))
    except (OSError, ValueError, KeyError, TypeError):
        return None


def holders(*, directory: Path | None = None) -> list[Holder]:
    """The records of every claim in the runtime directory (their holders may have died:
    the caller checks)."""
    return [holder for _, holder in _records(directory or runtime_dir())]


def _records(directory: Path) -> list[tuple[Path, Holder]]:
    found = []
    for path in sorted(directory.glob("*.json")):
        try:
            found.append((path, Holder.from_dict(json.loads(path.read_text()))))
        except (OSError, ValueError, KeyError, TypeError):
            continue
    return found


class BusClaim:
    """This process holds the bus (see the module docstring); release with
    :meth:`release` or as a context manager. Callbacks registered with
    :meth:`on_release` (the control socket's server) run on release."""

    def __init__(self, interface: str, channel: str, fd: int, holder: Holder,
                 directory: Path) -> None:
        self.interface = interface
        self.channel = channel
        self._fd: int | None = fd
        self._holder = holder
        self.directory = directory
        self.stem = _file_stem(interface, channel)
        self._on_release: list[Callable[[], None]] = []
        self._write_record()

    @property
    def name(self) -> str:
        return bus_name(self.interface, self.channel)

    @property
    def record_path(self) -> Path:
        return self.directory / f"{self.stem}.json"

    @property
    def socket_path(self) -> Path:
        """Where this claim's control socket lives (short: a unix socket path has ~100
        bytes)."""
        return self.directory / f"{self.stem[-10:]}.sock"

    @property
    def held(self) -> bool:
        return self._fd is not None

    def holder(self) -> Holder:
        return self._holder

    def set_socket(self, path: str | None) -> None:
        """Name the control socket in the record (None: none is served)."""
        from dataclasses import replace

        self._holder = replace(self._holder, socket=path)
        if self.held:
            self._write_record()

    def describe_arm(self, *, campaign: str | None, arm_id: str | None,
                     reach: tuple[str, ...]) -> None:
        """Name in the record the arm this claim is for (see the module docstring)."""
        from dataclasses import replace

        self._holder = replace(self._holder, campaign=campaign, arm_id=arm_id,
                               reach=tuple(reach))
        if self.held:
            self._write_record()

    def claim_arm(self, serials: str, described: str) -> None:
        """This claim's bus reaches the arm whose modules say ``serials``
        (ArmIdentity.key; ``described`` for the operator): refused when another live
        claim has the same arm through another bus (one arm reached over two endpoints,
        e.g. its adapter and a socketcand bridge, is still one arm: one controller);
        else the record names it.

        :raises ~seqrun.errors.Refused: naming the other holder and its bus.
        """
        from dataclasses import replace

        for other in _records(self.directory):
            path, holder = other
            if (path != self.record_path and holder.serials == serials
                    and not holder.transient and holder.alive()):
                raise Refused(f"the arm with {described} is driven by {holder.describe()} on "
                              f"{holder.bus or 'another bus'}: one controller per arm, "
                              "whichever bus reaches it")
        self._holder = replace(self._holder, serials=serials)
        if self.held:
            self._write_record()

    def on_release(self, callback: Callable[[], None]) -> None:
        self._on_release.append(callback)

    def _write_record(self) -> None:
        tmp = self.record_path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(json.dumps(self._holder.as_dict()))
        os.replace(tmp, self.record_path)

    def release(self) -> None:
        """Remove the record, then let the lock go (idempotent)."""
        if self._fd is None:
            return
        callbacks, self._on_release = self._on_release, []
        for callback in callbacks:
            try:
                callback()
            except Exception:  # noqa: BLE001 - releasing must not fail
                pass
        try:
            if read_holder(self.interface, self.channel,
                           directory=self.directory) == self._holder:
                self.record_path.unlink()
        except OSError:
            pass
        fd, self._fd = self._fd, None
        os.close(fd)   # the kernel drops the flock with the last descriptor

    def __enter__(self) -> BusClaim:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()

    def __del__(self) -> None:  # a claim nobody released still goes with the process
        fd = getattr(self, "_fd", None)
        if fd is not None:
            try:
                os.close(fd)
            except OSError:
                pass


def claim_bus(interface: str, channel: str, command: str | None = None, *,
              transient: bool = False, wait_s: float | None = None,
              directory: Path | None = None) -> BusClaim:
    """Claim the bus ``interface``/``channel`` for this process.

    :param command: the holder's command line for other processes' messages (default:
        this process's, :func:`command_line`).
    :param transient: this claim is held for a moment only (others wait for it).
    :param wait_s: how long to wait for a transient holder (default
        :data:`TRANSIENT_WAIT_S`); a holder that is not transient refuses at once.
    :raises ~seqrun.errors.Refused: another process holds the bus; the one-line message
        names it.
    """
    directory = _private_dir(directory or runtime_dir())
    stem = _file_stem(interface, channel)
    fd = os.open(directory / f"{stem}.lock", os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o600)
    start = time.monotonic()
    deadline = start + (TRANSIENT_WAIT_S if wait_s is None else wait_s)
    try:
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except OSError as exc:
                if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    raise
            holder = read_holder(interface, channel, directory=directory)
            now = time.monotonic()
            # No record yet: the holder has the lock and is about to write it.
            waiting = (now < start + 0.5 if holder is None
                       else holder.transient and now < deadline)
            if waiting:
                time.sleep(_POLL_S)
                continue
            raise Refused(refusal(interface, channel, holder))
    except BaseException:
        os.close(fd)
        raise
    holder = Holder(pid=os.getpid(), command=command or command_line(), since=time.time(),
                    argv=tuple(sys.argv), transient=transient, bus=bus_name(interface, channel),
                    started=process_start(os.getpid()))
    return BusClaim(interface, channel, fd, holder, directory)


def refusal(interface: str, channel: str, holder: Holder | None) -> str:
    """The one line a refused claimer prints."""
    who = holder.describe() if holder is not None else "another process (no record)"
    return (f"{bus_name(interface, channel)} is held by {who}: one controller per bus; "
            "'seqrun status' and 'seqrun halt' talk to it")
