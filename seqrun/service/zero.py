"""The zero reference: which pose the arm was powered off in, recorded.

The PowerCube modules take the position they are powered off in as their encoder zero, so
the offsets that turn module positions into user angles depend on that pose
(``power_off_poses`` of the arm file). seqrun keeps two facts per arm:

- ``record``: where the arm was last powered off (or lost power). Written by the
  ``power_off`` step at the end of a shutdown sequence, or by ``seqrun zero set POSE``.
  It becomes the zero reference at the next power-on, once the operator has confirmed
  that the arm stands in that pose.
- ``in_use``: the zero reference of the modules' current power session (confirmed at the
  last power-on). While the modules stay homed, runs use it: a ``power_off`` step that
  records Totem does not change the zeros of modules that are still on.

The file lives with the campaign (``<campaign>/.seqrun/zero.json``), else in a per-arm
state file under ``$SEQRUN_STATE_DIR`` (default ``$XDG_STATE_HOME/seqrun``, i.e.
``~/.local/state/seqrun``). Writes replace the file whole.
"""

from __future__ import annotations

import datetime as _dt
import getpass
import json
import os
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from seqrun.errors import UserInputError

#: Overrides where per-arm state files go (tests, shared machines).
STATE_DIR_ENV = "SEQRUN_STATE_DIR"


def state_dir() -> Path:
    if os.environ.get(STATE_DIR_ENV):
        return Path(os.environ[STATE_DIR_ENV])
    base = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    return Path(base) / "seqrun"


def _slug(text: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "-" for c in text).strip("-")[:80] or "arm"


def _user() -> str:
    try:
        return getpass.getuser()
    except Exception:  # no login name (containers): still record the change
        return "unknown"


@dataclass(frozen=True)
class ZeroRecord:
    """One zero-reference fact: the pose, when, by what (a sequence or a command), who."""

    pose: str
    recorded_at: str  # ISO 8601, local time with offset
    by: str
    user: str = ""

    def describe(self, pose_title: str | None = None) -> str:
        """``Totem, recorded 2026-11-20 17:03 by shutdown.yaml``."""
        try:
            when = _dt.datetime.fromisoformat(self.recorded_at).strftime("%Y-%m-%d %H:%M")
        except ValueError:
            when = self.recorded_at
        who = f" ({self.user})" if self.user else ""
        return f"{pose_title or self.pose.capitalize()}, recorded {when} by {self.by}{who}"

    @classmethod
    def now(cls, pose: str, by: str) -> "ZeroRecord":
        stamp = _dt.datetime.now().astimezone().isoformat(timespec="seconds")
        return cls(pose=pose, recorded_at=stamp, by=by, user=_user())

    @classmethod
    def from_dict(cls, data: Any) -> "ZeroRecord | None":
        if not isinstance(data, dict) or not isinstance(data.get("pose"), str):
            return None
        return cls(pose=data["pose"], recorded_at=str(data.get("recorded_at", "")),
                   by=str(data.get("by", "")), user=str(data.get("user", "")))


class ZeroStore:
    """The zero-reference file of one arm (campaign file or per-arm state file)."""

    def __init__(self, path: Path, arm_name: str, set_command: str = "seqrun zero set POSE") -> None:
        self.path = Path(path)
        self.arm_name = arm_name
        #: The command an operator types to write this record.
        self.set_command = set_command

    @classmethod
    def for_arm(cls, arm_name: str, project: Any = None) -> "ZeroStore":
        """The campaign's file when ``project`` is a campaign, else the per-arm state file."""
        if project is not None and getattr(project, "is_campaign", False):
            return cls(project.root / ".seqrun" / "zero.json", arm_name,
                       f"seqrun zero set POSE --project {project.root}")
        return cls(state_dir() / f"zero-{_slug(arm_name)}.json", arm_name)

    def _read(self) -> dict:
        try:
            data = json.loads(self.path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            return {}
        except (OSError, ValueError) as exc:
            raise UserInputError(f"zero-reference file {self.path} cannot be read ({exc}); "
                                 "set the reference again with 'seqrun zero set POSE'") from None
        arms = data.get("arms") if isinstance(data, dict) else None
        entry = arms.get(self.arm_name) if isinstance(arms, dict) else None
        return entry if isinstance(entry, dict) else {}

    @property
    def record(self) -> ZeroRecord | None:
        """Where the arm was last powered off (the zero reference of the next power-on)."""
        return ZeroRecord.from_dict(self._read().get("record"))

    @property
    def in_use(self) -> ZeroRecord | None:
        """The zero reference confirmed at the current power-on (modules still homed)."""
        return ZeroRecord.from_dict(self._read().get("in_use"))

    def _write(self, **changes: ZeroRecord) -> None:
        try:
            data = json.loads(self.path.read_text(encoding="utf-8"))
            if not isinstance(data, dict) or not isinstance(data.get("arms"), dict):
                data = {}
        except (OSError, ValueError):
            data = {}
        data.setdefault("arms", {})
        entry = data["arms"].setdefault(self.arm_name, {})
        entry.update({key: asdict(value) for key, value in changes.items()})
        self.path.parent.mkdir(parents=True, exist_ok=True)
        temporary = self.path.with_name(self.path.name + ".tmp")
        temporary.write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
        os.replace(temporary, self.path)

    def set_record(self, pose: str, by: str) -> ZeroRecord:
        """Record that the arm is (about to be) powered off in ``pose``."""
        record = ZeroRecord.now(pose, by)
        self._write(record=record)
        return record

    def set_in_use(self, record: ZeroRecord) -> None:
        """The operator confirmed ``record`` at a power-on: the modules' zeros are there."""
        self._write(in_use=record)


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

    def as_dict(self) -> dict:
        return {"pose": self.pose, "text": self.text, "source": self.source,
                "after_power_on": self.after_power_on,
                "record": asdict(self.record) if self.record is not None else None}


def pose_title(name: str) -> str:
    return name.replace("_", " ").capitalize() if name.islower() else name


def _joints_text(arm, pose: str) -> str:
    return ", ".join(f"{n} {v:g}°" for n, v in arm.power_off_joints_deg(pose).items())


def zero_for_run(arm, store: ZeroStore, *, simulator_pose: str | None,
                 homed: bool) -> ZeroInForce:
    """Which zero reference a run uses.

    ``simulator_pose``: the built-in simulator's power-on pose (its modules read zero
    there, so that is the truth; nobody needs asking). ``homed``: every module reports
    HOME_OK, i.e. no power-on since the last confirmed start. Raises
    :class:`UserInputError` when the arm may not move: no record, or a record of a pose
    the arm file does not have.
    """
    if not arm.power_off_poses:
        return ZeroInForce(None, "zero: the arm file's offsets (it names no power-off poses)",
                           "arm_file", not homed)
    if simulator_pose is not None:
        arm.power_off_pose(simulator_pose)  # a pose the arm has
        return ZeroInForce(simulator_pose.lower(),
                           f"zero: {pose_title(simulator_pose)} (the simulator's power-on pose)",
                           "simulator", not homed)
    how = (f"say where the arm was powered off with '{store.set_command}' "
           f"(POSE: {', '.join(arm.power_off_poses)})")
    record: ZeroRecord | None
    if homed and store.in_use is not None:
        record = store.in_use
        arm.power_off_pose(record.pose)
        return ZeroInForce(record.pose, f"zero: {record.describe(pose_title(record.pose))} "
                           "(confirmed at this power-on)", "in_use", False, record)
    record = store.record
    if record is None:
        raise UserInputError(f"no zero reference recorded for arm '{arm.name}' "
                             f"({store.path}): nothing will move; {how}")
    try:
        arm.power_off_pose(record.pose)
    except UserInputError as exc:
        raise UserInputError(f"zero reference in {store.path}: {exc}; {how}") from None
    question = (f"The modules take their zero where they were powered off. Does the arm "
                f"stand in {pose_title(record.pose)} now ({_joints_text(arm, record.pose)})?")
    return ZeroInForce(record.pose, f"zero: {record.describe(pose_title(record.pose))}",
                       "record", True, record, question)
