"""``seqrun ik``: joint angles that put the tool at a pose (inverse kinematics).

    seqrun ik --position-mm -136.3 510.8 389.8 --rpy-deg -22.3 -27.5 124.4
    seqrun ik --position-mm 0 400 300 --rpy-deg 180 0 90 --near opsafe --json
    seqrun ik --position-mm 0 400 300 --rpy-deg 180 0 90 --near-deg 70 30 0 70 20 50 0

The solution nearest the seed (``--near POSE``, ``--near-deg …``, default Totem) is
printed; a target no configuration inside the joint limits reaches is one ``error:`` line
with the residual, exit 1.
"""

from __future__ import annotations

import json
import math
from typing import Annotated

import typer

from seqrun.cli.app import app
from seqrun.cli.common import (EXIT_INVALID, ArmOption, OneArmOption, PosesDirOption, fail,
                               load_arm_file, user_errors)
from seqrun.cli.fk import ValuesAfterOption, parse_angles
from seqrun.cli.pose import format_numbers, load_named_pose
from seqrun.errors import UserInputError
from seqrun.defaults import DEFAULT_ARM, DEFAULT_POSES_DIR


class IkCommand(ValuesAfterOption):
    value_options = ("--position-mm", "--rpy-deg", "--near-deg")


def _three(tokens: list[str] | None, option: str) -> list[float]:
    if tokens is None or len(tokens) != 3:
        raise UserInputError(f"{option} needs 3 numbers, got {0 if tokens is None else len(tokens)}")
    values = []
    for token in tokens:
        try:
            value = float(token)
        except ValueError:
            raise UserInputError(f"{option}: '{token}' is not a number") from None
        if not math.isfinite(value):
            raise UserInputError(f"{option}: '{token}' is not a finite number")
        values.append(value)
    return values


@app.command("ik", cls=IkCommand)
def inverse_kinematics(
    position_mm: Annotated[list[str] | None, typer.Option(
        "--position-mm", metavar="X Y Z", help="Tool position in the base frame, mm.")] = None,
    rpy_deg: Annotated[list[str] | None, typer.Option(
        "--rpy-deg", metavar="R P Y",
        help="Tool orientation, roll/pitch/yaw in degrees (R = Rz(yaw) Ry(pitch) Rx(roll)).")
    ] = None,
    near: Annotated[str | None, typer.Option(
        "--near", metavar="POSE", help="Seed: prefer the solution nearest this pose file's "
                                       "joints (default: Totem, all zeros).")] = None,
    near_deg: Annotated[list[str] | None, typer.Option(
        "--near-deg", metavar="Q1 ... Qn", help="Seed as joint angles, one per joint, locked "
                                                "ones too.")] = None,
    tool: Annotated[str | None, typer.Option(
        "--tool", metavar="NAME", help="Tool of the arm file whose centre point goes to the "
                                       "target (default: the arm's default_tool, else the "
                                       "end-effector frame).")] = None,
    as_json: Annotated[bool, typer.Option(
        "--json", help='Print {"joints_deg", "position_error_mm", "angle_error_deg", ...}.')
    ] = False,
    arm_file: ArmOption = DEFAULT_ARM,
    poses_dir: PosesDirOption = DEFAULT_POSES_DIR,
    arm_id: OneArmOption = None,
) -> None:
    """Joint angles (user degrees) that put the tool at a position and orientation, inside
    the joint limits, with the locked joints at their value. Exit 1 if unreachable."""
    import numpy as np

    from seqrun.service.kinematics import inverse_kinematics

    with user_errors():
        position = _three(position_mm, "--position-mm")
        rpy = _three(rpy_deg, "--rpy-deg")
        if near is not None and near_deg is not None:
            raise UserInputError("give either --near or --near-deg, not both")
        arm = load_arm_file(arm_file, arm_id)
        if near_deg is not None:
            seed_values: list[float] | dict[str, float] = parse_angles(near_deg, arm.joint_names)
        elif near is not None:
            seed_values = load_named_pose(near, poses_dir).joints_deg
        else:
            seed_values = {j.name: 0.0 for j in arm.joints if j.locked is None}
        ik = inverse_kinematics(arm, position, rpy, tool=tool, seed=seed_values)
    if ik.solution is None:
        fail(str(ik.unreachable), EXIT_INVALID)
    solution, seed = ik.solution, ik.seed_deg
    joints = solution.joints_deg
    if as_json:
        typer.echo(json.dumps({
            "joints_deg": {n: round(float(v), 6) + 0.0 for n, v in zip(arm.joint_names, joints)},
            "position_error_mm": float(f"{solution.position_error_mm:.3g}"),
            "angle_error_deg": float(f"{math.degrees(solution.angle_error_rad):.3g}"),
            "iterations": solution.iterations, "seeds_tried": solution.seeds_tried,
            "tool": ik.tool}))
        return
    typer.echo(f"joints_deg    {format_numbers(np.round(joints, 6) + 0.0)}  ({' '.join(arm.joint_names)})")
    moved = np.abs(joints - np.asarray(seed))
    typer.echo(f"residual      {solution.position_error_mm:.2g} mm, "
               f"{math.degrees(solution.angle_error_rad):.2g} deg; largest joint change from "
               f"the seed {float(moved.max()):.3f} deg")


__all__ = ["IkCommand"]
