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
  last power-on) and the power-session mark then left in the modules' RAM
  (``ArmDriver.write_session_mark``). While the modules read that mark back, runs use it:
  a ``power_off`` step that records Totem does not change the zeros of modules that are
  still on. A power cycle erases the mark; HOME_OK says nothing about it (modules may
  power on homed, ``seqrun home`` sets it). An ``in_use`` whose mark is gone is cleared.

Both hold the pose's joint angles themselves (user degrees), with the pose's name: the
offsets follow from the angles, never from what an arm file says that name means today.
A record of an older seqrun (format 2) names a pose only: its angles are taken from the
arm file in use and it always needs the operator's word again (its ``in_use`` is dropped:
it has no mark), after which it is written in this format.

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
import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
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
FORMAT = "seqrun zero reference 3"
#: The format before the joint angles and the power-session mark (read, then migrated).
OLD_FORMAT = "seqrun zero reference 2"
#: Two angles closer than this (degrees) are the same pose.
SAME_ANGLE_DEG = 1e-6
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


def _same_angles(a: Mapping[str, float], b: Mapping[str, float]) -> bool:
    return sorted(a) == sorted(b) and all(abs(a[n] - b[n]) <= SAME_ANGLE_DEG for n in a)


def _finite_numbers(values: Any) -> bool:
    return isinstance(values, dict) and all(
        isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
        for v in values.values())


@dataclass(frozen=True)
class ZeroRecord:
    """One zero-reference fact: the pose (a power-off pose of the arm file by name, or
    ``POSE_IN_DEGREES``) with its joint angles, when, by what (a sequence or a command),
    who."""

    pose: str
    recorded_at: str  # ISO 8601, local time with offset
    by: str
    user: str = ""
    #: User degrees by joint name: where the arm stood. None only in a record of an older
    #: seqrun (a pose name alone): its angles are unknown until the operator confirms.
    joints_deg: dict[str, float] | None = None

    @property
    def by_name_only(self) -> bool:
        """An older seqrun's record: a pose name, no angles."""
        return self.joints_deg is None

    def title(self) -> str:
        if self.pose == POSE_IN_DEGREES and self.joints_deg is not None:
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
        """Where the arm stands (user degrees) in this pose: the recorded angles (an older
        record's: the arm file's angles of its pose name)."""
        if self.joints_deg is not None:
            return dict(self.joints_deg)
        return arm.power_off_joints_deg(self.pose)

    def check(self, arm: ArmDescription) -> None:
        """UserInputError unless ``arm`` agrees with this record: the same joints, and a
        power-off pose of the same name at the same angles (an arm file whose "totem"
        stands elsewhere than the recorded Totem must not drive with either)."""
        if self.joints_deg is None:
            arm.power_off_pose(self.pose)
            return
        if sorted(self.joints_deg) != sorted(arm.joint_names):
            raise UserInputError(f"the recorded pose names joints {', '.join(self.joints_deg)}"
                                 f"; the arm has {', '.join(arm.joint_names)}")
        if self.pose != POSE_IN_DEGREES:
            try:
                file_angles = arm.power_off_joints_deg(self.pose)
            except UserInputError:
                return  # a pose this arm file does not name: the angles say it all
            if not _same_angles(file_angles, self.joints_deg):
                raise UserInputError(
                    f"the recorded {pose_title(self.pose)} is {_degrees(self.joints_deg)}; "
                    f"arm '{arm.name}' says {self.pose} is {_degrees(file_angles)}: the "
                    "arm file and the record disagree, nothing will move")

    def apply(self, arm: ArmDescription) -> ArmDescription:
        """``arm`` with the offsets of this power-off pose (its angles; a pose of the arm
        file at the same angles by its name, which keeps that name in force)."""
        if self.joints_deg is None or (self.pose != POSE_IN_DEGREES
                                       and self.pose.lower() in {
                                           p.lower() for p in arm.power_off_poses}):
            return arm.with_zero_reference(self.pose)
        return arm.with_power_off_joints(self.joints_deg)

    def with_angles(self, arm: ArmDescription) -> ZeroRecord:
        """This record with its angles written down (an older record's from ``arm``)."""
        if self.joints_deg is not None:
            return self
        return replace(self, joints_deg=self.stands_at(arm))

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
        if joints is not None and not _finite_numbers(joints):
            return None
        return cls(pose=data["pose"], recorded_at=str(data.get("recorded_at", "")),
                   by=str(data.get("by", "")), user=str(data.get("user", "")),
                   joints_deg=None if joints is None else
                   {str(n): float(v) for n, v in joints.items()})


@dataclass(frozen=True)
class ZeroInUse:
    """The zero confirmed at the modules' current power-on: the record confirmed (with
    its angles) and the power-session mark then left in the modules (None: they could
    not keep one, so every command asks again)."""

    record: ZeroRecord
    session_mark: int | None

    def as_dict(self) -> dict:
        return {**self.record.as_dict(), "session_mark": self.session_mark}

    @classmethod
    def from_dict(cls, data: Any) -> ZeroInUse | None:
        record = ZeroRecord.from_dict(data)
        if record is None or record.joints_deg is None:
            return None  # an older seqrun's: no angles, no mark
        mark = data.get("session_mark")
        if mark is not None and (isinstance(mark, bool) or not isinstance(mark, int)):
            return None
        return cls(record, mark)


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
        if not isinstance(data, dict) or data.get("format") not in (FORMAT, OLD_FORMAT):
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
    def in_use(self) -> ZeroInUse | None:
        """The zero reference confirmed at a power-on, and the mark then left in the
        modules (it is in use while they read that mark back). An older seqrun's entry
        (no angles, no mark) is None."""
        return ZeroInUse.from_dict(self._read().get("in_use"))

    def _write(self, arm_name: str | None = None,
               **changes: ZeroRecord | ZeroInUse | None) -> None:
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
        for key, value in changes.items():
            if value is None:
                fields.pop(key, None)
            else:
                fields[key] = value.as_dict()
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

    def set_record(self, pose: str, by: str, *, joints_deg: Mapping[str, float],
                   arm_name: str | None = None) -> ZeroRecord:
        """Record that the arm is (about to be) powered off in ``pose`` (a power-off pose's
        name, or ``POSE_IN_DEGREES``) standing at ``joints_deg``."""
        record = ZeroRecord.now(pose, by, joints_deg)
        self._write(arm_name, record=record)
        return record

    def set_in_use(self, record: ZeroRecord, session_mark: int | None,
                   arm_name: str | None = None) -> ZeroInUse:
        """The operator confirmed ``record`` (with its angles) at a power-on: the modules'
        zeros are there, and they hold ``session_mark`` (None: they cannot keep one). An
        older seqrun's record is written again with the angles confirmed."""
        assert record.joints_deg is not None, "the angles confirmed are written down"
        in_use = ZeroInUse(record, session_mark)
        current = self.record
        if current is not None and current.by_name_only and current.pose == record.pose:
            self._write(arm_name, in_use=in_use, record=record)
        else:
            self._write(arm_name, in_use=in_use)
        return in_use

    def holds_in_use(self) -> bool:
        """The file has an ``in_use`` entry (of any format)."""
        return "in_use" in self._read()

    def clear_in_use(self) -> None:
        """The modules were powered off since the zero in use was confirmed: forget it."""
        self._write(None, in_use=None)

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
    #: The power-session mark the modules hold while this zero is theirs (None: the
    #: simulator, an arm file without power-off poses, modules that keep no mark).
    session_mark: int | None = None

    def apply(self, arm: ArmDescription) -> ArmDescription:
        """``arm`` with the offsets of this zero reference."""
        if self.record is not None:
            return self.record.apply(arm)
        return arm.with_zero_reference(self.pose)

    def stands_at(self, arm: ArmDescription) -> dict[str, float] | None:
        """The angles of the power-off pose of this zero (None: the arm file's offsets)."""
        if self.record is not None:
            return self.record.stands_at(arm)
        return None if self.pose is None else arm.power_off_joints_deg(self.pose)

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
                 simulator_pose: str | None, session_mark: int | None) -> ZeroInForce:
    """Which zero reference a run uses.

    ``simulator_pose``: the built-in simulator's power-on pose (its modules read zero
    there, so that is the truth; nobody needs asking). ``store``: the connected arm's own
    record (None only with ``simulator_pose``). ``session_mark``: the power-session mark
    the modules hold now (``ArmDriver.session_mark``): the zero confirmed at this power-on
    is in use only while it is the one left then; otherwise the modules were powered off
    since (or never confirmed), that ``in_use`` is cleared, and the record needs the
    operator's word. Raises :class:`UserInputError` when the arm may not move: no record,
    a record the arm file disagrees with, or a file that cannot be trusted.
    """
    if not arm.power_off_poses:
        return ZeroInForce(None, "zero: the arm file's offsets (it names no power-off poses)",
                           "arm_file", session_mark is None)
    if simulator_pose is not None:
        arm.power_off_pose(simulator_pose)  # a pose the arm has
        return ZeroInForce(simulator_pose.lower(),
                           f"zero: {pose_title(simulator_pose)} (the simulator's power-on pose)",
                           "simulator", True)
    assert store is not None, "a real arm's zero needs its store"
    how = (f"say where the arm was powered off with '{store.set_command}' on its bus "
           f"(POSE: {', '.join(arm.power_off_poses)}; any other pose: --deg Q1 ... Qn)")
    in_use = store.in_use
    if (in_use is not None and in_use.session_mark is not None
            and in_use.session_mark == session_mark):
        try:
            in_use.record.check(arm)
        except UserInputError as exc:
            raise UserInputError(f"zero reference in {store.path}: {exc}; {how}") from None
        return ZeroInForce(in_use.record.pose, f"zero: {in_use.record.describe()} (confirmed "
                           "at this power-on)", "in_use", False, in_use.record, store=store,
                           session_mark=session_mark)
    if in_use is not None or store.holds_in_use():
        store.clear_in_use()  # its power session is over (or it has no mark to tell)
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
    older = (" (recorded by an older seqrun by name only: these are this arm file's angles "
             "of it)" if record.by_name_only else "")
    question = (f"The modules take their zero where they were powered off. Does the arm "
                f"stand in {record.title()} now ({_degrees(record.stands_at(arm))}){older}?")
    return ZeroInForce(record.pose, f"zero: {record.describe()}", "record", True, record,
                       question, store=store)


# --------------------------------------------------------------------------- the decision
class ZeroNotConfirmed(UserInputError):
    """The operator said the arm does not stand in the recorded pose: nothing moves."""


def _confirmed_matches(zero: ZeroInForce, arm: ArmDescription, confirmed: str) -> bool:
    """``--zero-confirmed POSE`` names the pose of ``zero``: the same *angles* (a name
    the arm file gives other angles than the record is not that pose)."""
    truth = zero.stands_at(arm)
    if truth is None:
        return False
    try:
        said = arm.power_off_joints_deg(confirmed.strip())
    except UserInputError:
        return False
    return _same_angles(said, truth)


def confirmed_per_arm(values: Sequence[str], arm_ids: Sequence[str | None]
                      ) -> dict[str | None, str]:
    """``--zero-confirmed`` as given (repeatable) for the arms of a command: arm id ->
    the pose the operator says that arm stands in. ``ID=POSE`` names one arm's; a bare
    ``POSE`` is every arm's (an ``ID=POSE`` overrides it for that arm). An arm named by
    none is absent (its zero is asked as usual). The pose itself is checked where the
    zero is decided (:func:`zero_at_start`), for each arm as for one.

    :raises UserInputError: one line: an unknown arm, an empty pose, an arm (or every arm)
        named twice, ``ID=POSE`` for an arm that has no id.
    """
    bare: str | None = None
    named: dict[str | None, str] = {}
    ids = [a for a in arm_ids if a is not None]
    for value in values:
        arm, sep, pose = value.partition("=")
        arm, pose = arm.strip(), pose.strip()
        if not sep:
            if not arm:
                raise UserInputError("--zero-confirmed '': name the pose the arm stands in "
                                     "(e.g. park)")
            if bare is not None:
                raise UserInputError(f"--zero-confirmed {bare} and {arm}: one pose for every "
                                     "arm, or ID=POSE for each arm")
            bare = arm
            continue
        if not ids:
            raise UserInputError(f"--zero-confirmed {value}: this arm has no id (it is not "
                                 "one of a campaign's [arms.ID]): give the pose alone")
        if arm not in ids:
            raise UserInputError(f"--zero-confirmed {value}: no arm '{arm}' here (arms "
                                 f"{', '.join(ids)})")
        if not pose:
            raise UserInputError(f"--zero-confirmed {value}: name the pose arm {arm} stands "
                                 f"in (e.g. {arm}=park)")
        if arm in named:
            raise UserInputError(f"--zero-confirmed: arm {arm} named twice "
                                 f"({arm}={named[arm]}, {value})")
        named[arm] = pose
    if bare is None:
        return named
    return {a: named.get(a, bare) for a in arm_ids}


def _new_mark(previous: int | None) -> int:
    import secrets

    from seqrun.drivers.base import SESSION_MARK_LIMIT

    while True:
        mark = 1 + secrets.randbelow(SESSION_MARK_LIMIT - 1)
        if mark != previous:
            return mark


def zero_at_start(connection: Any, arm: ArmDescription, *, ask: Callable[[str], bool],
                  show: Callable[[str], None], confirmed: str | None = None,
                  store: ZeroStore | None = None) -> ZeroInForce:
    """Decide the zero reference of a run (or a console) on ``connection``, show it, and
    on real hardware after a power-on have the operator confirm the pose before anything
    moves: ``ask(question)``, or ``confirmed`` (``--zero-confirmed POSE``: the operator's
    explicit word, never ``--yes``), which must name the zero reference in force (its
    angles). Once confirmed, a new power-session mark is left in the modules.

    ``store``: the arm's store when the caller holds it already; else the arm's identity
    is read from its modules and its store opened here.

    :raises UserInputError: no record, a file that cannot be trusted, a ``confirmed``
        pose that is not the one in force (nothing moves).
    :raises ZeroNotConfirmed: the operator said no.
    :raises ~seqrun.errors.BusError: the modules did not answer.
    """
    from seqrun.service.arm_access import identity_and_session_mark, leave_session_mark

    if connection.is_simulator:
        zero = zero_for_run(arm, None, session_mark=None,
                            simulator_pose=connection.power_on_pose)
    else:
        identity, mark = identity_and_session_mark(connection, arm)
        if store is None:
            store = ZeroStore(identity)
        elif store.identity != identity:
            raise UserInputError(f"the zero reference given is that of the arm with "
                                 f"{store.identity.describe()}; the connected modules say "
                                 f"{identity.describe()}: refused, nothing will move")
        zero = zero_for_run(arm, store, session_mark=mark, simulator_pose=None)
    show(zero.text)
    if confirmed is not None and not _confirmed_matches(zero, arm, confirmed):
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
        record = zero.record.with_angles(arm)
        new_mark = _new_mark(None)
        kept = leave_session_mark(connection, arm, new_mark)
        if not kept:
            show("note: the modules do not keep a power-session mark: the zero is asked "
                 "again at every command")
        zero.store.set_in_use(record, new_mark if kept else None, arm.name)
        zero = replace(zero, record=record, session_mark=new_mark if kept else None)
    return zero


def _zero_now(connection: Any, arm: ArmDescription) -> ZeroInForce:
    from seqrun.service.arm_access import identity_and_session_mark

    if connection.is_simulator:
        return zero_for_run(arm, None, session_mark=None,
                            simulator_pose=connection.power_on_pose)
    identity, mark = identity_and_session_mark(connection, arm)
    return zero_for_run(arm, ZeroStore(identity), session_mark=mark, simulator_pose=None)


def zero_for_reading(connection: Any, arm: ArmDescription) -> tuple[ArmDescription, str]:
    """The arm with the zero reference in force for reading positions (status): ``(arm,
    text)``. Never asks and never refuses (nothing moves); without a usable record the
    text says the positions use the arm file's offsets."""
    from seqrun.errors import BusError

    try:
        zero = _zero_now(connection, arm)
    except (UserInputError, BusError) as exc:
        return arm, (f"zero: unknown ({exc}); positions use the arm file's offsets "
                     f"({arm.default_power_off or 'as written'})")
    text = zero.text + (" (not yet confirmed at this power-on)" if zero.question else "")
    return zero.apply(arm), text


def confirmed_zero_for_reading(connection: Any,
                               arm: ArmDescription) -> tuple[ArmDescription, str]:
    """As :func:`zero_for_reading`, for what is kept (``pose save``): UserInputError unless
    the zero was confirmed at this power-on (angles measured against an assumed zero
    would send every later move elsewhere)."""
    zero = _zero_now(connection, arm)
    if zero.question is not None:
        raise UserInputError(
            f"{zero.text.removeprefix('zero: ')} is not confirmed at this power-on: nothing "
            "saved; confirm it first (seqrun home --zero-confirmed POSE, or any run)")
    return zero.apply(arm), zero.text
