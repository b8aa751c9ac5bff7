"""``seqrun fk``: the end-effector pose at given joint angles (or at a named pose).

    seqrun fk --deg 0 -90 0 -120.32 0 115.74 0
    seqrun fk --pose park --json

Negative angles are typed as they are: click reads ``-90`` as an option, so this command
reads every value after ``--deg`` up to the next option itself (:class:`ValuesAfterOption`).
"""

from __future__ import annotations

import json
import math
from typing import TYPE_CHECKING, Annotated, Any, ClassVar

import typer
from typer.core import TyperCommand

from seqrun.cli.app import app
from seqrun.cli.common import (ArmOption, OneArmOption, PosesDirOption, load_arm_file,
                               user_errors)
from seqrun.cli.pose import format_numbers, load_named_pose
from seqrun.defaults import DEFAULT_ARM, DEFAULT_POSES_DIR
from seqrun.errors import UserInputError

if TYPE_CHECKING:
    import numpy as np

    from seqrun.arm.kinematics import Pose

_JSON_DECIMALS = 6  # 1 nm, 1e-6 deg: far below what the arm can do, and readable


def _is_number(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


class ValuesAfterOption(TyperCommand):
    """A command whose ``value_options`` take several values: ``--deg 0 -90 0``.

    Before click parses, ``--deg a b c`` becomes ``--deg a --deg b --deg c`` (the option is
    declared ``multiple``); a single value may start with ``-``, so negative numbers survive.
    The values run until the next token that is an option and not a number, or ``--``.
    """

    value_options: ClassVar[tuple[str, ...]] = ()

    def parse_args(self, ctx: Any, args: list[str]) -> list[str]:
        return super().parse_args(ctx, self.spread_values(args))

    @classmethod
    def spread_values(cls, args: list[str]) -> list[str]:
        spread: list[str] = []
        position = 0
        while position < len(args):
            token = args[position]
            position += 1
            if token == "--":  # end of options: the rest is not ours to touch
                return spread + [token] + args[position:]
            if token not in cls.value_options:
                spread.append(token)
                continue
            values = []
            while position < len(args) and not _ends_values(args[position]):
                values.append(args[position])
                position += 1
            if not values:
                spread.append(token)  # click reports the missing value
            for value in values:
                spread += [token, value]
        return spread


def _ends_values(token: str) -> bool:
    return token == "--" or (token.startswith("-") and not _is_number(token))


class FkCommand(ValuesAfterOption):
    value_options = ("--deg",)


def parse_angles(tokens: list[str], joint_names: list[str]) -> list[float]:
    """Degrees from the command line; :class:`UserInputError` naming the bad value."""
    if len(tokens) != len(joint_names):
        raise UserInputError(f"--deg needs {len(joint_names)} angles "
                             f"({' '.join(joint_names)}), got {len(tokens)}")
    angles = []
    for name, token in zip(joint_names, tokens):
        try:
            value = float(token)
        except ValueError:
            raise UserInputError(f"--deg: {name} '{token}' is not a number") from None
        if not math.isfinite(value):
            raise UserInputError(f"--deg: {name} '{token}' is not a finite angle")
        angles.append(value)
    return angles


def _rounded(values: np.ndarray) -> list:
    import numpy as np

    # + 0.0 turns -0.0 into 0.0
    return (np.round(np.asarray(values, dtype=float), _JSON_DECIMALS) + 0.0).tolist()


def pose_json(pose: Pose) -> str:
    return json.dumps({"position_mm": _rounded(pose.position_mm),
                       "rpy_deg": _rounded(pose.rpy_deg),
                       "rotation": _rounded(pose.rotation)})


def pose_text(pose: Pose) -> str:
    rows = [f"{' ' * 14}{format_numbers(row, 6)}" for row in pose.rotation]
    rows[0] = "rotation" + rows[0][8:]
    return "\n".join([f"position_mm   {format_numbers(pose.position_mm)}",
                      f"rpy_deg       {format_numbers(pose.rpy_deg)}", *rows])


@app.command("fk", cls=FkCommand)
def forward_kinematics(
    deg: Annotated[list[str] | None, typer.Option(
        "--deg", metavar="Q1 ... Qn",
        help="Joint angles in user degrees (Totem = zeros), one per joint, locked ones too; "
             "negative values as they are: --deg 0 -90 0 -120.32 0 115.74 0.")] = None,
    pose_name: Annotated[str | None, typer.Option(
        "--pose", metavar="NAME", help="Use the joints of a pose file instead of --deg.")] = None,
    as_json: Annotated[bool, typer.Option(
        "--json", help='Print {"position_mm", "rpy_deg", "rotation"} as JSON.')] = False,
    arm_file: ArmOption = DEFAULT_ARM,
    poses_dir: PosesDirOption = DEFAULT_POSES_DIR,
    arm_id: OneArmOption = None,
) -> None:
    """End-effector pose (position mm, roll/pitch/yaw deg, rotation matrix) by forward
    kinematics, R = Rz(yaw) Ry(pitch) Rx(roll)."""
    from seqrun.service.kinematics import forward_kinematics as pose_of_joints

    with user_errors():
        if deg is None and pose_name is None:
            raise UserInputError("give the joint angles with --deg Q1 ... Qn or a pose with "
                                 "--pose NAME")
        if deg is not None and pose_name is not None:
            raise UserInputError("give either --deg or --pose, not both")
        arm = load_arm_file(arm_file, arm_id)
        if deg is not None:
            joints: list[float] | dict[str, float] = parse_angles(deg, arm.joint_names)
        else:
            assert pose_name is not None  # (one of the two, checked above)
            joints = load_named_pose(pose_name, poses_dir).joints_deg
        fk = pose_of_joints(arm, joints)
    for note in fk.notes:  # a maths command: what was asked, and what the arm would not do
        typer.echo(note, err=True)
    typer.echo(pose_json(fk.pose) if as_json else pose_text(fk.pose))


__all__ = ["FkCommand", "ValuesAfterOption", "parse_angles", "pose_json", "pose_text"]
