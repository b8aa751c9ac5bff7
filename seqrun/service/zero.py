"""The zero reference: which pose the arm was powered off in, recorded per physical arm.

The PowerCube modules take the position they are powered off in as their encoder zero, so
the offsets that turn module positions into user angles depend on that pose
(``power_off_poses`` of the arm file, or any pose given in degrees). seqrun keeps two facts
per arm:

- ``record``: where the arm was last powered off (or lost power). Written by the
  ``power_off`` step at the end of a shutdown sequence, or by ``seqrun zero set POSE`` /
  ``seqrun zero set --deg Q1 ... Q7``. It becomes the zero reference at the next
  power-on, once the operator has confirmed that the arm stands in that pose.
- ``in_use``: the zero reference of the modules' current power session (confirmed at the
  last power-on). While the modules stay homed, runs use it: a ``power_off`` step that
  records Totem does not change the zeros of modules that are still on.

Both belong to the physical arm, not to an arm file, a user or a campaign: the store is
keyed by the arm's identity (its modules' serial numbers, read at connect through the
driver) and kept once per arm on this machine, in ``$SEQRUN_STATE_DIR/arms/`` (default
``/var/lib/seqrun/arms/``), shared by every user and every campaign. The file names the
serials it belongs to and carries a checksum of its fields: a file of another arm, or one
edited by hand, is refused (one line saying how to record the pose again), never used.
Writes replace the file whole.
"""

from __future__ import annotations

import datetime as _dt
import getpass
import hashlib
import json
import os
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from seqrun.errors import UserInputError

if TYPE_CHECKING:
    from seqrun.arm.description import ArmDescription
    from seqrun.drivers.base import ArmIdentity

#: Overrides where this machine's arm records go (tests, a machine set up otherwise).
STATE_DIR_ENV = "SEQRUN_STATE_DIR"
#: This machine's state: shared by every user (docs/safety.md says how to create it).
MACHINE_STATE_DIR = Path("/var/lib/seqrun")
#: The file format (a file of another format is refused, not guessed at).
FORMAT = "seqrun zero reference 2"
#: ``ZeroRecord.pose`` of a record given in degrees (``seqrun zero set --deg``).
POSE_IN_DEGREES = "joints"
#: The command that records the zero reference (the operator adds the arm's bus options).
SET_COMMAND = "seqrun zero set POSE"


def state_dir() -> Path:
    """This machine's seqrun state: ``$SEQRUN_STATE_DIR``, else ``/var/lib/seqrun``."""
    if os.environ.get(STATE_DIR_ENV):
        return Path(os.environ[STATE_DIR_ENV])
    return MACHINE_STATE_DIR


def older_records(start: Path | None = None) -> list[Path]:
    """Zero records an older seqrun kept per arm *type*: per user
    (``$XDG_STATE_HOME/seqrun/zero-*.json``) and per campaign (``.seqrun/zero.json`` in the
    current folder or above). They cannot say which physical arm they were taken on, so they
    are never used; a refusal names them so that the operator knows why the arm is asked for
    again."""
    base = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    found = sorted((Path(base) / "seqrun").glob("zero-*.json"))
    here = (start or Path.cwd()).resolve()
    for folder in (here, *here.parents):
        campaign_file = folder / ".seqrun" / "zero.json"
        if campaign_file.is_file():
            found.append(campaign_file)
            break
    return found


def _user() -> str:
    try:
        return getpass.getuser()
    except Exception:  # no login name (containers): still record the change
        return "unknown"


def _degrees(values: Mapping[str, float]) -> str:
    return ", ".join(f"{n} {v:g}°" for n, v in values.items())


@dataclass(frozen=True)
class ZeroRecord:
    """One zero-reference fact: the pose (a power-off pose of the arm file, or joint
    angles given in degrees), when, by what (a sequence or a command), who."""

    pose: str
    recorded_at: str  # ISO 8601, local time with offset
    by: str
    user: str = ""
    #: User degrees by joint name when the pose was given in degrees (pose "joints").
    joints_deg: dict[str, float] | None = None

    def title(self) -> str:
        if self.joints_deg is not None:
            return f"the pose {_degrees(self.joints_deg)}"
        return pose_title(self.pose)

    def describe(self, title: str | None = None) -> str:
        """``Totem, recorded 2026-11-20 17:03 by shutdown.yaml``."""
        try:
            when = _dt.datetime.fromisoformat(self.recorded_at).strftime("%Y-%m-%d %H:%M")
        except ValueError:
            when = self.recorded_at
        who = f" ({self.user})" if self.user else ""
        return f"{title or self.title()}, recorded {when} by {self.by}{who}"

    def stands_at(self, arm: ArmDescription) -> dict[str, float]:
        """Where the arm stands (user degrees) in this pose."""
        if self.joints_deg is not None:
            return dict(self.joints_deg)
        return arm.power_off_joints_deg(self.pose)

    def check(self, arm: ArmDescription) -> None:
        """UserInputError unless ``arm`` has this pose (or these joints)."""
        if self.joints_deg is None:
            arm.power_off_pose(self.pose)
        elif sorted(self.joints_deg) != sorted(arm.joint_names):
            raise UserInputError(f"the recorded pose names joints {', '.join(self.joints_deg)}"
                                 f"; the arm has {', '.join(arm.joint_names)}")

    def apply(self, arm: ArmDescription) -> ArmDescription:
        """``arm`` with the offsets of this power-off pose."""
        if self.joints_deg is not None:
            return arm.with_power_off_joints(self.joints_deg)
        return arm.with_zero_reference(self.pose)

    def as_dict(self) -> dict:
        data = asdict(self)
        if self.joints_deg is None:
            del data["joints_deg"]
        return data

    @classmethod
    def now(cls, pose: str, by: str,
            joints_deg: Mapping[str, float] | None = None) -> ZeroRecord:
        stamp = _dt.datetime.now().astimezone().isoformat(timespec="seconds")
        return cls(pose=pose, recorded_at=stamp, by=by, user=_user(),
                   joints_deg=None if joints_deg is None else
                   {n: float(v) for n, v in joints_deg.items()})

    @classmethod
    def from_dict(cls, data: Any) -> ZeroRecord | None:
        if not isinstance(data, dict) or not isinstance(data.get("pose"), str):
            return None
        joints = data.get("joints_deg")
        if joints is not None and not (isinstance(joints, dict) and all(
                isinstance(v, (int, float)) and not isinstance(v, bool)
                for v in joints.values())):
            return None
        return cls(pose=data["pose"], recorded_at=str(data.get("recorded_at", "")),
                   by=str(data.get("by", "")), user=str(data.get("user", "")),
                   joints_deg=None if joints is None else
                   {str(n): float(v) for n, v in joints.items()})


def _checksum(fields: Mapping[str, Any]) -> str:
    """SHA-256 of the fields in one canonical form: any change to them shows."""
    text = json.dumps(fields, sort_keys=True, separators=(",", ":"), ensure_ascii=True)
    return "sha256:" + hashlib.sha256(text.encode("ascii")).hexdigest()


class ZeroStore:
    """The zero-reference file of one physical arm on this machine.

    :param identity: the arm's identity, read at connect (``ArmDriver.identity()``).
    :param folder: where this machine keeps its arms' records (default
        ``state_dir() / "arms"``).
    """

    def __init__(self, identity: ArmIdentity, folder: Path | None = None) -> None:
        self.identity = identity
        self.folder = Path(folder) if folder is not None else state_dir() / "arms"
        digest = hashlib.sha256(identity.key.encode("utf-8")).hexdigest()[:16]
        self.path = self.folder / f"arm-{digest}.json"
        #: The command an operator types to write this record.
        self.set_command = SET_COMMAND

    def _again(self) -> str:
        return (f"record where the arm was powered off again with '{self.set_command}' "
                "(or --deg Q1 ... Qn) on this arm's bus")

    def _read(self) -> dict:
        """The file's fields (empty when there is none); UserInputError for a file that
        cannot be trusted."""
        try:
            data = json.loads(self.path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            return {}
        except (OSError, ValueError) as exc:
            raise UserInputError(f"zero-reference file {self.path} cannot be read ({exc}): "
                                 f"nothing will move; {self._again()}") from None
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise UserInputError(f"zero-reference file {self.path} is not a seqrun zero "
                                 f"reference ({FORMAT!r}): nothing will move; "
                                 f"{self._again()}")
        fields = {k: v for k, v in data.items() if k != "checksum"}
        if data.get("checksum") != _checksum(fields):
            raise UserInputError(f"zero-reference file {self.path} was changed outside "
                                 "seqrun (its checksum does not match its fields): it is not "
                                 f"used and nothing will move; {self._again()}")
        serials = (data.get("arm") or {}).get("serials") if isinstance(data.get("arm"),
                                                                        dict) else None
        mine = {str(m): s for m, s in self.identity.serials}
        if serials != mine:
            theirs = ", ".join(f"{m}:{s}" for m, s in (serials or {}).items()) or "none"
            raise UserInputError(f"zero-reference file {self.path} belongs to the arm with "
                                 f"serials {theirs}, not to the connected modules "
                                 f"({self.identity.describe()}): refused, nothing will move; "
                                 f"record this arm's power-off pose with "
                                 f"'{self.set_command}' on its bus")
        return fields

    @property
    def record(self) -> ZeroRecord | None:
        """Where the arm was last powered off (the zero reference of the next power-on)."""
        return ZeroRecord.from_dict(self._read().get("record"))

    @property
    def in_use(self) -> ZeroRecord | None:
        """The zero reference confirmed at the current power-on (modules still homed)."""
        return ZeroRecord.from_dict(self._read().get("in_use"))

    def _write(self, arm_name: str | None = None, **changes: ZeroRecord) -> None:
        """Replace the file whole; a record that cannot be trusted is replaced too (it is
        what ``seqrun zero set`` is for)."""
        try:
            fields = self._read()
        except UserInputError:
            fields = {}
        fields["format"] = FORMAT
        arm = dict(fields.get("arm") or {})
        arm["serials"] = {str(m): s for m, s in self.identity.serials}
        if arm_name:
            arm["name"] = arm_name
        fields["arm"] = arm
        fields.update({key: value.as_dict() for key, value in changes.items()})
        fields["checksum"] = _checksum(fields)
        temporary = self.path.with_name(f".{self.path.name}.{os.getpid()}.tmp")
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            temporary.write_text(json.dumps(fields, indent=2) + "\n", encoding="utf-8")
            os.chmod(temporary, 0o664)  # every operator of this machine writes it
            os.replace(temporary, self.path)
        except OSError as exc:
            try:
                temporary.unlink()
            except OSError:
                pass
            raise UserInputError(
                f"cannot write the zero reference to {self.path} ({exc.strerror or exc}); "
                f"it is this machine's, shared by every operator: create the folder once "
                f"(sudo install -d -m 2775 -g GROUP {self.folder}) or set {STATE_DIR_ENV}"
            ) from None

    def set_record(self, pose: str, by: str, *, joints_deg: Mapping[str, float] | None = None,
                   arm_name: str | None = None) -> ZeroRecord:
        """Record that the arm is (about to be) powered off in ``pose`` (for a pose given
        in degrees: ``POSE_IN_DEGREES`` and ``joints_deg``)."""
        record = ZeroRecord.now(pose, by, joints_deg)
        self._write(arm_name, record=record)
        return record

    def set_in_use(self, record: ZeroRecord, arm_name: str | None = None) -> None:
        """The operator confirmed ``record`` at a power-on: the modules' zeros are there."""
        self._write(arm_name, in_use=record)

    def related(self) -> list[tuple[Path, list[int]]]:
        """Other arms' records on this machine that share modules (by serial number) with
        this arm: ``(file, shared module ids)``; a module exchanged shows here."""
        mine = set(self.identity.serials)
        found = []
        for path in sorted(self.folder.glob("arm-*.json")) if self.folder.is_dir() else []:
            if path == self.path:
                continue
            try:
                serials = json.loads(path.read_text(encoding="utf-8"))["arm"]["serials"]
                theirs = {(int(m), str(s)) for m, s in serials.items()}
            except (OSError, ValueError, KeyError, TypeError, AttributeError):
                continue
            if shared := sorted(m for m, _ in mine & theirs):
                found.append((path, shared))
        return found


# --------------------------------------------------------------------------- at run start
@dataclass(frozen=True)
class ZeroInForce:
    """The zero reference a run uses, and what the operator must be asked about it."""

    pose: str | None  # None: the arm file names no power-off poses (its offsets as written)
    text: str  # "zero: Totem, recorded 2026-11-20 17:03 by shutdown.yaml"
    source: str  # simulator | record | in_use | arm_file
    after_power_on: bool
    record: ZeroRecord | None = None
    question: str | None = None  # asked before anything moves (real hardware, power-on)
    #: The arm's own store (None for the simulator and an arm file without power-off poses).
    store: ZeroStore | None = field(default=None, compare=False, repr=False)

    def apply(self, arm: ArmDescription) -> ArmDescription:
        """``arm`` with the offsets of this zero reference."""
        if self.record is not None:
            return self.record.apply(arm)
        return arm.with_zero_reference(self.pose)

    def as_dict(self) -> dict:
        return {"pose": self.pose, "text": self.text, "source": self.source,
                "after_power_on": self.after_power_on,
                "record": self.record.as_dict() if self.record is not None else None,
                "arm": None if self.store is None else self.store.identity.by_module()}


def pose_title(name: str) -> str:
    if name == POSE_IN_DEGREES:
        return "the pose given in degrees"
    return name.replace("_", " ").capitalize() if name.islower() else name


def zero_for_run(arm: ArmDescription, store: ZeroStore | None, *,
                 simulator_pose: str | None, homed: bool) -> ZeroInForce:
    """Which zero reference a run uses.

    ``simulator_pose``: the built-in simulator's power-on pose (its modules read zero
    there, so that is the truth; nobody needs asking). ``store``: the connected arm's own
    record (None only with ``simulator_pose``). ``homed``: every module reports HOME_OK,
    i.e. no power-on since the last confirmed start. Raises :class:`UserInputError` when
    the arm may not move: no record, a record of a pose the arm file does not have, or a
    file that cannot be trusted.
    """
    if not arm.power_off_poses:
        return ZeroInForce(None, "zero: the arm file's offsets (it names no power-off poses)",
                           "arm_file", not homed)
    if simulator_pose is not None:
        arm.power_off_pose(simulator_pose)  # a pose the arm has
        return ZeroInForce(simulator_pose.lower(),
                           f"zero: {pose_title(simulator_pose)} (the simulator's power-on pose)",
                           "simulator", not homed)
    assert store is not None, "a real arm's zero needs its store"
    how = (f"say where the arm was powered off with '{store.set_command}' on its bus "
           f"(POSE: {', '.join(arm.power_off_poses)}; any other pose: --deg Q1 ... Qn)")
    record: ZeroRecord | None
    if homed and (record := store.in_use) is not None:
        try:
            record.check(arm)
        except UserInputError as exc:
            raise UserInputError(f"zero reference in {store.path}: {exc}; {how}") from None
        return ZeroInForce(record.pose, f"zero: {record.describe()} (confirmed at this "
                           "power-on)", "in_use", False, record, store=store)
    record = store.record
    if record is None:
        related = store.related()
        hint = "".join(f"; {path} holds the record of an arm with module(s) "
                       f"{', '.join(map(str, shared))} of these serials (a module exchanged? "
                       "its zero is unknown)" for path, shared in related[:1])
        hint += "".join(f"; {path} is an older seqrun's record per arm type, not of this "
                        "arm: it is not used" for path in older_records()[:1])
        raise UserInputError(f"no zero reference recorded for this arm "
                             f"({store.identity.describe()}; {store.path}): nothing will "
                             f"move; {how}{hint}")
    try:
        record.check(arm)
    except UserInputError as exc:
        raise UserInputError(f"zero reference in {store.path}: {exc}; {how}") from None
    question = (f"The modules take their zero where they were powered off. Does the arm "
                f"stand in {record.title()} now ({_degrees(record.stands_at(arm))})?")
    return ZeroInForce(record.pose, f"zero: {record.describe()}", "record", True, record,
                       question, store=store)


# --------------------------------------------------------------------------- the decision
class ZeroNotConfirmed(UserInputError):
    """The operator said the arm does not stand in the recorded pose: nothing moves."""


def _confirmed_matches(zero: ZeroInForce, confirmed: str) -> bool:
    said = confirmed.strip().lower()
    return zero.pose is not None and said == zero.pose.lower()


def zero_at_start(connection: Any, arm: ArmDescription, *, ask: Callable[[str], bool],
                  show: Callable[[str], None], confirmed: str | None = None,
                  store: ZeroStore | None = None) -> ZeroInForce:
    """Decide the zero reference of a run (or a console) on ``connection``, show it, and
    on real hardware after a power-on have the operator confirm the pose before anything
    moves: ``ask(question)``, or ``confirmed`` (``--zero-confirmed POSE``: the operator's
    explicit word, never ``--yes``), which must name the zero reference in force.

    ``store``: the arm's store when the caller holds it already; else the arm's identity
    is read from its modules and its store opened here.

    :raises UserInputError: no record, a file that cannot be trusted, a ``confirmed``
        pose that is not the one in force (nothing moves).
    :raises ZeroNotConfirmed: the operator said no.
    :raises ~seqrun.errors.BusError: the modules did not answer.
    """
    from seqrun.service.arm_access import identity_and_homed

    if connection.is_simulator:
        zero = zero_for_run(arm, None, homed=False, simulator_pose=connection.power_on_pose)
    else:
        identity, homed = identity_and_homed(connection, arm)
        if store is None:
            store = ZeroStore(identity)
        elif store.identity != identity:
            raise UserInputError(f"the zero reference given is that of the arm with "
                                 f"{store.identity.describe()}; the connected modules say "
                                 f"{identity.describe()}: refused, nothing will move")
        zero = zero_for_run(arm, store, homed=homed, simulator_pose=None)
    show(zero.text)
    if confirmed is not None and not _confirmed_matches(zero, confirmed):
        raise UserInputError(f"--zero-confirmed {confirmed}: the zero reference in force is "
                             f"{zero.text.removeprefix('zero: ')}; nothing was sent")
    if zero.question is not None:
        if confirmed is not None:
            show(f"{zero.question} yes (--zero-confirmed {confirmed})")
        elif not ask(zero.question):
            raise ZeroNotConfirmed(
                "Not started: the operator says the arm is not in the recorded power-off "
                "pose. Nothing was sent. Record the pose it was really powered off in with "
                f"'{SET_COMMAND}' (or --deg Q1 ... Qn) and run again.")
        assert zero.record is not None and zero.store is not None  # asked about a record
        zero.store.set_in_use(zero.record, arm.name)
    return zero


def zero_for_reading(connection: Any, arm: ArmDescription) -> tuple[ArmDescription, str]:
    """The arm with the zero reference in force for reading positions (status, pose save):
    ``(arm, text)``. Never asks and never refuses (nothing moves); without a usable record
    the text says the positions use the arm file's offsets."""
    from seqrun.errors import BusError
    from seqrun.service.arm_access import identity_and_homed

    try:
        if connection.is_simulator:
            zero = zero_for_run(arm, None, homed=False,
                                simulator_pose=connection.power_on_pose)
        else:
            identity, homed = identity_and_homed(connection, arm)
            zero = zero_for_run(arm, ZeroStore(identity), homed=homed, simulator_pose=None)
    except (UserInputError, BusError) as exc:
        return arm, (f"zero: unknown ({exc}); positions use the arm file's offsets "
                     f"({arm.default_power_off or 'as written'})")
    text = zero.text + (" (not yet confirmed at this power-on)" if zero.question else "")
    return zero.apply(arm), text
