"""Pose files ``poses/<name>.yaml``: named joint configurations in user degrees.

A pose file stores every joint of the arm (the locked one too) and, for the reader, the
end-effector pose that forward kinematics gives for those joints. The joints are the truth;
:func:`check_pose` says when the stored end-effector no longer agrees with them (an edited
file, a changed arm description).
"""

from __future__ import annotations

import functools
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field

from seqrun.arm.description import ArmDescription
from seqrun.defaults import START_POSE
from seqrun.errors import UserInputError
from seqrun.arm.kinematics import matrix_from_rpy, orientation_error, pose_from_user_deg

__all__ = [
    "DEFAULT_POSES_DIR",
    "NOTE_PREFIX",
    "EndEffector",
    "PoseFile",
    "PoseFinding",
    "PoseSource",
    "available_poses",
    "check_pose_name",
    "check_pose",
    "find_pose",
    "pose_overrides",
    "load_pose",
    "park_deg",
    "pose_document",
    "pose_findings",
    "pose_joints_deg",
    "pose_yaml",
    "save_pose",
]

#: Pose directory used when none is given (relative to the project root / cwd).
from seqrun.defaults import DEFAULT_POSES_DIR  # noqa: E402

#: First line of every pose file: editors with yaml-language-server validate against it.
SCHEMA_COMMENT = "# yaml-language-server: $schema=../docs/schema/pose.schema.json"

#: How far the stored end-effector may be from forward kinematics before check_pose objects.
#: Stored values are rounded to 0.001, far inside these.
POSITION_TOLERANCE_MM = 0.5
ORIENTATION_TOLERANCE_DEG = 0.1

#: check_pose findings that start with this are information, not problems.
NOTE_PREFIX = "note: "

_POSE_NAME = r"^[A-Za-z0-9][A-Za-z0-9_-]*$"
_DECIMALS = 3  # stored end-effector: 1 µm, 0.001 deg

Finite = Annotated[float, Field(allow_inf_nan=False)]
Triple = tuple[Finite, Finite, Finite]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class EndEffector(_Strict):
    position_mm: Triple = Field(description="End-effector position [x, y, z] in the base frame, mm.")
    rpy_deg: Triple = Field(
        description="Orientation [roll, pitch, yaw] in degrees, R = Rz(yaw) Ry(pitch) Rx(roll).")


class PoseFile(_Strict):
    """One pose file (``poses/<name>.yaml``)."""

    name: str = Field(pattern=_POSE_NAME,
                      description="Pose name used on the command line and in sequences; "
                                  "the file is poses/<name>.yaml.")
    description: str = Field("", description="What the pose is for.")
    arm: str = Field(description="Name of the arm description the pose was made for.")
    source: Literal["reference", "arm", "simulator", "manual"] | None = Field(
        None, description="Where the joints come from: reference (documented values), "
                          "arm (read from the modules), simulator (read from the "
                          "simulated arm), manual (typed in).")
    saved_at: datetime | None = Field(None, description="When the pose was saved (ISO 8601).")
    joints_deg: dict[str, Finite] = Field(
        min_length=1,
        description="Every joint of the arm (locked ones too) in user degrees (Totem = zeros).")
    end_effector: EndEffector = Field(
        description="End-effector pose computed by forward kinematics from joints_deg; "
                    "for the reader, checked against the joints.")


def load_pose(path: str | Path) -> PoseFile:
    """Load and validate one pose file; raises :class:`seqrun.errors.SequenceInvalid`."""
    from seqrun.yamlsource import load_model  # local import: yamlsource is a sibling layer

    return load_model(Path(path), PoseFile)


PoseDirs = str | Path | Sequence[str | Path]


def _search_path(poses_dir: PoseDirs) -> list[Path]:
    """One folder, or a search path (first match wins: a campaign's, then the shipped)."""
    if isinstance(poses_dir, (str, Path)):
        return [Path(poses_dir)]
    return [Path(p) for p in poses_dir]


def _files(folder: Path) -> dict[str, Path]:
    if not folder.is_dir():
        return {}
    return {p.stem: p for p in sorted(folder.glob("*.yaml")) if p.is_file()}


def available_poses(poses_dir: PoseDirs) -> dict[str, Path]:
    """Pose name -> file for every ``*.yaml`` in ``poses_dir`` (a folder or a search path,
    where the first folder that has a name wins), sorted by name."""
    found: dict[str, Path] = {}
    for folder in _search_path(poses_dir):
        for name, path in _files(folder).items():
            found.setdefault(name, path)
    return dict(sorted(found.items()))


def pose_overrides(poses_dir: PoseDirs) -> dict[str, tuple[Path, list[Path]]]:
    """Poses defined in more than one folder of a search path: name -> (the file used,
    the files it hides)."""
    seen: dict[str, list[Path]] = {}
    for folder in _search_path(poses_dir):
        for name, path in _files(folder).items():
            seen.setdefault(name, []).append(path)
    return {name: (paths[0], paths[1:]) for name, paths in sorted(seen.items())
            if len(paths) > 1}


def find_pose(name: str, poses_dir: PoseDirs) -> Path:
    """The file of pose ``name``; :class:`UserInputError` listing the known poses and the
    folders searched otherwise."""
    poses = available_poses(poses_dir)
    if name in poses:
        return poses[name]
    folders = _search_path(poses_dir)
    if len(folders) == 1:
        if not folders[0].is_dir():
            raise UserInputError(f"unknown pose '{name}': pose directory {folders[0]} "
                                 "does not exist")
        where = f"in {folders[0]}"
    else:
        where = "searched " + ", ".join(
            f"{f}" + ("" if f.is_dir() else " (does not exist)") for f in folders)
    known = ", ".join(poses) if poses else "none"
    raise UserInputError(f"unknown pose '{name}'; available poses: {known} ({where})")


#: Where a pose is looked up by name: the poses a sequence froze when it was loaded (name
#: -> an object with ``joints_deg``, or a joint mapping; a run uses only these), or a pose
#: folder or search path.
PoseSource = Mapping[str, Any] | PoseDirs


def pose_joints_deg(name: str, poses: PoseSource) -> dict[str, float]:
    """Joint angles of pose ``name`` (user degrees), from the poses frozen with a sequence
    or from a pose folder or search path (first match wins, as :func:`find_pose`). Raises
    :class:`UserInputError` for an unknown pose (or one the sequence did not read),
    :class:`SequenceInvalid` for a broken pose file."""
    if isinstance(poses, Mapping):
        if name not in poses:
            raise UserInputError(f"pose '{name}' was not read with the sequence")
        entry: Any = poses[name]
        return dict(entry.joints_deg if hasattr(entry, "joints_deg") else entry)
    path = find_pose(name, poses)
    return dict(_pose_joints(path, path.stat().st_mtime_ns))


@functools.lru_cache(maxsize=64)
def _pose_joints(path: Path, mtime_ns: int) -> tuple[tuple[str, float], ...]:
    # Keyed on the file's mtime: a pose file edited between runs is read again.
    return tuple(load_pose(path).joints_deg.items())


def park_deg(poses_dir: PoseDirs) -> dict[str, float]:
    """The default start state: the Park pose (where a freshly powered-on arm is)."""
    return pose_joints_deg(START_POSE, poses_dir)


def _stored_number(value: float) -> float:
    # round for the reader; + 0.0 turns -0.0 into 0.0 so files never show "-0.0"
    return round(float(value), _DECIMALS) + 0.0


def check_pose_name(name: str) -> None:
    """:class:`UserInputError` (one clear line) for a name a pose file cannot have."""
    import re

    if not re.match(_POSE_NAME, name):
        raise UserInputError(f"'{name}' is not a pose name: letters, digits, _ and -, "
                             "starting with a letter or digit (it names the file "
                             "poses/<name>.yaml)")


def pose_document(name: str, arm: ArmDescription,
                  joints_deg: Sequence[float] | Mapping[str, float],
                  description: str = "", source: str | None = None,
                  saved_at: datetime | None = None) -> PoseFile:
    """A pose file for the arm at ``joints_deg`` (user degrees), end-effector by FK.

    Accepts what :func:`seqrun.arm.kinematics.pose_from_user_deg` accepts (a locked joint may be
    left out of a mapping); raises ``ValueError`` for unknown, missing or wrong joints and
    :class:`UserInputError` for a name that is not a pose name.
    """
    check_pose_name(name)
    pose = pose_from_user_deg(arm, joints_deg)
    if isinstance(joints_deg, Mapping):
        given: dict[str, Any] = {n: joints_deg.get(n, j.locked)  # (a left-out joint: locked)
                                 for n, j in zip(arm.joint_names, arm.joints)}
    else:
        given = dict(zip(arm.joint_names, joints_deg))
    return PoseFile(
        name=name, description=description, arm=arm.name, source=source, saved_at=saved_at,
        joints_deg={n: float(v) + 0.0 for n, v in given.items()},
        end_effector=EndEffector(position_mm=tuple(map(_stored_number, pose.position_mm)),
                                 rpy_deg=tuple(map(_stored_number, pose.rpy_deg))),
    )


class _PoseDumper(yaml.SafeDumper):
    """Block mappings, one-line lists (``position_mm: [x, y, z]``), folded long texts."""


def _flow_list(dumper: yaml.SafeDumper, data: list) -> yaml.Node:
    return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=True)


_UNICODE_LINE_BREAKS = ("\x85", "\u2028", "\u2029")


def _readable_str(dumper: yaml.SafeDumper, data: str) -> yaml.Node:
    style = None
    if any(ch in data for ch in _UNICODE_LINE_BREAKS):
        style = '"'  # only double quotes escape them; elsewhere they read back as line breaks
    elif len(data) > 60 and "\n" not in data and data == data.strip():
        style = ">"  # long texts as folded blocks: wrapped, unquoted, read back as one line
    return dumper.represent_scalar("tag:yaml.org,2002:str", data, style=style)


_PoseDumper.add_representer(list, _flow_list)
_PoseDumper.add_representer(str, _readable_str)


def _dump(data: dict) -> str:
    return yaml.dump(data, Dumper=_PoseDumper, sort_keys=False, default_flow_style=False,
                     allow_unicode=True, width=92)


def pose_yaml(pose: PoseFile) -> str:
    """The text of a pose file: schema comment, then name/description/arm first, the
    joints, and last the computed end-effector."""
    header = pose.model_dump(include={"name", "description", "arm", "source"},
                             exclude_none=True)  # in field order
    if pose.saved_at is not None:
        header["saved_at"] = pose.saved_at.isoformat()
    return "".join([
        SCHEMA_COMMENT + "\n",
        _dump(header),
        "# user degrees (Totem = all zeros); locked joints at their locked value\n",
        _dump({"joints_deg": dict(pose.joints_deg)}),
        "# computed from joints_deg by forward kinematics (mm, deg; R = Rz(yaw) Ry(pitch) Rx(roll))\n",
        _dump({"end_effector": {"position_mm": list(pose.end_effector.position_mm),
                                "rpy_deg": list(pose.end_effector.rpy_deg)}}),
    ])


def save_pose(path: str | Path, pose: PoseFile) -> None:
    """Write ``pose`` to ``path``; the file is replaced whole, never left half written."""
    path = Path(path)
    temporary = path.with_name(path.name + ".tmp")
    temporary.write_text(pose_yaml(pose), encoding="utf-8")
    os.replace(temporary, path)


@dataclass(frozen=True)
class PoseFinding:
    """One finding of :func:`pose_findings`: ``where`` is the path of the value in the
    file (e.g. ``("joints_deg", "j2")``), ``key``: at the key rather than the value."""

    where: tuple[str, ...]
    message: str
    note: bool = False
    key: bool = False
    joint: str | None = None  # the joint a limit note is about


def pose_findings(pose: PoseFile, arm: ArmDescription) -> list[PoseFinding]:
    """Problems of a pose for ``arm`` (and notes), each with where it is in the file.

    Problems: another arm, unknown or missing joints, a locked joint away from its locked
    value, a stored end-effector that disagrees with FK of the joints (beyond
    :data:`POSITION_TOLERANCE_MM` / :data:`ORIENTATION_TOLERANCE_DEG`). Notes: joints outside
    their limits (allowed: Park is outside, a sequence starting there moves back inside).
    """
    findings: list[PoseFinding] = []
    if pose.arm != arm.name:
        findings.append(PoseFinding(("arm",), f"made for arm '{pose.arm}', not '{arm.name}'"))
    unknown = [name for name in pose.joints_deg if name not in arm.joint_names]
    missing = [name for name in arm.joint_names if name not in pose.joints_deg]
    if unknown:
        findings.append(PoseFinding(("joints_deg", unknown[0]),
                                    f"unknown joint(s) {', '.join(unknown)}; "
                                    f"the arm has {', '.join(arm.joint_names)}", key=True))
    if missing:
        findings.append(PoseFinding(("joints_deg",), f"missing joint(s) {', '.join(missing)}",
                                    key=True))
    for joint in arm.joints:
        value = pose.joints_deg.get(joint.name)
        if value is None:
            continue
        if joint.locked is not None and not math.isclose(value, joint.locked, abs_tol=1e-6):
            findings.append(PoseFinding(("joints_deg", joint.name),
                                        f"{joint.name} is locked at {joint.locked:g} deg, "
                                        f"the pose has {value:g}"))
        lo, hi = joint.limits_deg
        if not lo <= value <= hi:
            findings.append(PoseFinding(("joints_deg", joint.name),
                                        f"{joint.name} {value:g} deg is outside its limits "
                                        f"[{lo:g}, {hi:g}]", note=True, joint=joint.name))
    if missing or unknown:
        return findings  # no end-effector to compare with

    # The arm holds a locked joint at its locked value whatever the file says.
    joints = {j.name: (j.locked if j.locked is not None else pose.joints_deg[j.name])
              for j in arm.joints}
    computed = pose_from_user_deg(arm, joints)
    stored = pose.end_effector
    distance = float(np.linalg.norm(np.subtract(stored.position_mm, computed.position_mm)))
    if distance > POSITION_TOLERANCE_MM:
        findings.append(PoseFinding(("end_effector", "position_mm"),
                                    f"end_effector.position_mm {_triple(stored.position_mm)} is "
                                    f"{distance:.3f} mm from forward kinematics "
                                    f"{_triple(computed.position_mm)}"))
    angle = math.degrees(float(orientation_error(
        matrix_from_rpy(np.radians(stored.rpy_deg)), computed.rotation)))
    if angle > ORIENTATION_TOLERANCE_DEG:
        findings.append(PoseFinding(("end_effector", "rpy_deg"),
                                    f"end_effector.rpy_deg {_triple(stored.rpy_deg)} is "
                                    f"{angle:.3f} deg from forward kinematics "
                                    f"{_triple(computed.rpy_deg)}"))
    return findings


def check_pose(pose: PoseFile, arm: ArmDescription) -> list[str]:
    """:func:`pose_findings` as text; notes start with :data:`NOTE_PREFIX`."""
    return [(NOTE_PREFIX if f.note else "") + f.message for f in pose_findings(pose, arm)]


def _triple(values: Iterable[float]) -> str:
    return "[" + ", ".join(f"{v:.3f}" for v in values) + "]"
