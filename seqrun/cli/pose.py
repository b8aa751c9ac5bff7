"""``seqrun pose list``, ``seqrun pose show NAME`` and ``seqrun pose save NAME``."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from seqrun.arm import DEFAULT_ARM
from seqrun.cli.app import pose_app
from seqrun.cli.common import (EXIT_INVALID, ArmOption, PosesDirOption, load_arm_file, user_errors)
from seqrun.errors import SequenceInvalid, UserInputError
from seqrun.poses import (
    DEFAULT_POSES_DIR,
    NOTE_PREFIX,
    PoseFile,
    available_poses,
    check_pose,
    find_pose,
    load_pose,
)

def load_named_pose(name: str, poses_dir: Path) -> PoseFile:
    return load_pose(find_pose(name, poses_dir))


def format_numbers(values, decimals: int = 3) -> str:
    return "[" + ", ".join(f"{float(v) + 0.0:.{decimals}f}" for v in values) + "]"


@pose_app.command("list")
def list_poses(poses_dir: PosesDirOption = DEFAULT_POSES_DIR) -> None:
    """List the pose files: name, source and description."""
    with user_errors():
        poses = available_poses(poses_dir)
        if not poses:
            raise UserInputError(f"no pose files in {poses_dir}")
        width = max(len(name) for name in poses)
        for name, path in poses.items():
            try:
                pose = load_pose(path)
            except SequenceInvalid as exc:  # one broken file must not hide the others
                typer.echo(f"{name:<{width}}  (invalid: {exc.errors[0]})")
                continue
            summary = pose.description.split(". ")[0]  # the first sentence; `show` has it all
            typer.echo(f"{name:<{width}}  {pose.source or '-':<9}  {summary}")


@pose_app.command("show")
def show_pose(
    name: Annotated[str, typer.Argument(help="Pose name (file poses/<name>.yaml).")],
    poses_dir: PosesDirOption = DEFAULT_POSES_DIR,
    arm_file: ArmOption = DEFAULT_ARM,
) -> None:
    """Show a pose and check it against the arm (exit 1 if it has problems)."""
    with user_errors():
        pose = load_named_pose(name, poses_dir)
        arm = load_arm_file(arm_file)
    typer.echo(f"name          {pose.name}")
    typer.echo(f"description   {pose.description}")
    typer.echo(f"arm           {pose.arm}")
    typer.echo(f"source        {pose.source or '-'}")
    if pose.saved_at is not None:
        typer.echo(f"saved_at      {pose.saved_at.isoformat()}")
    joints = ", ".join(f"{joint} {value:g}" for joint, value in pose.joints_deg.items())
    typer.echo(f"joints_deg    {joints}")
    typer.echo(f"position_mm   {format_numbers(pose.end_effector.position_mm)}")
    typer.echo(f"rpy_deg       {format_numbers(pose.end_effector.rpy_deg)}")
    findings = check_pose(pose, arm)
    problems = [f for f in findings if not f.startswith(NOTE_PREFIX)]
    for finding in findings:
        typer.echo(finding if finding.startswith(NOTE_PREFIX) else f"problem: {finding}",
                   err=True)
    if problems:
        raise typer.Exit(EXIT_INVALID)
