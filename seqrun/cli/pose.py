"""``seqrun pose list``, ``seqrun pose show NAME`` and ``seqrun pose save NAME``."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Optional

import typer

from seqrun.cli.app import pose_app
from seqrun.cli.common import (BitrateOption, BusKwargsOption, ChannelOption, InterfaceOption,
                               SimOption, connect, fail,
                               EXIT_INVALID, ArmOption, PosesDirOption, load_arm_file, user_errors)
from seqrun.defaults import DEFAULT_ARM, DEFAULT_POSES_DIR
from seqrun.errors import SequenceInvalid, UserInputError

if TYPE_CHECKING:
    from seqrun.arm.poses import PoseFile


def load_named_pose(name: str, poses_dir: Path) -> PoseFile:
    from seqrun.cli.common import pose_search_path
    from seqrun.arm.poses import find_pose, load_pose

    return load_pose(find_pose(name, pose_search_path(poses_dir)))


def format_numbers(values, decimals: int = 3) -> str:
    # Rounded first, then + 0.0: -0.0001 prints as 0.000, not -0.000.
    return "[" + ", ".join(f"{round(float(v), decimals) + 0.0:.{decimals}f}"
                           for v in values) + "]"


@pose_app.command("list")
def list_poses(poses_dir: PosesDirOption = DEFAULT_POSES_DIR) -> None:
    """List the pose files: name, source and description."""
    from seqrun.arm.poses import available_poses, load_pose

    with user_errors():
        from seqrun.cli.common import pose_search_path

        poses = available_poses(pose_search_path(poses_dir))
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
    from seqrun.arm.poses import NOTE_PREFIX, check_pose

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


@pose_app.command("save")
def save_pose_command(
    name: Annotated[str, typer.Argument(help="Pose name (file name without .yaml).")],
    output: Annotated[Optional[Path], typer.Option(
        "-o", "--output", metavar="FILE", help="Pose file to write (default poses/NAME.yaml).")] = None,
    description: Annotated[str, typer.Option("--description", "-d",
                                             help="What the pose is for.")] = "",
    force: Annotated[bool, typer.Option("--force", help="Overwrite an existing file.")] = False,
    poses_dir: PosesDirOption = DEFAULT_POSES_DIR,
    arm_file: ArmOption = DEFAULT_ARM, interface: InterfaceOption = None,
    channel: ChannelOption = None, bitrate: BitrateOption = None,
    bus_kwargs: BusKwargsOption = None, sim: SimOption = False,
) -> None:
    """Read the arm's joints and write them as a pose file (with the FK pose and the time).

    Reads the arm on the configured bus; the built-in simulator only with --sim (its arm
    always starts at Park, so a pose saved from it is marked source: simulator).
    """
    from datetime import datetime, timezone

    from seqrun.errors import BusError
    from seqrun.arm.poses import check_pose_name, pose_document, save_pose

    with user_errors():
        check_pose_name(name)  # before anything is opened
        arm = load_arm_file(arm_file)
        path = output or (poses_dir / f"{name}.yaml")
        if path.exists() and not force:
            fail(f"{path} exists (use --force to overwrite)")
        connection, driver = connect(arm, interface, channel, bitrate, bus_kwargs, sim)
    if connection.is_simulator and not sim:
        driver.close()
        connection.close()
        fail("no CAN interface configured: pose save reads the arm on a bus (-i/-c or "
             "python-can's configuration); give --sim to read the built-in simulator")
    if connection.is_simulator:
        typer.secho(connection.description, fg="yellow", bold=True, err=True)
    try:
        from seqrun.cli.zero import zero_for_reading

        arm, zero_text = zero_for_reading(connection, arm)
        typer.echo(zero_text)
        driver.use_arm(arm)
        reading = driver.read()
    except BusError as exc:
        fail(f"cannot read the arm: {exc}", 3)
    finally:
        driver.close()
        connection.close()
    joints = {j.name: round(float(x), 3)
              for j, x in zip(arm.joints, reading.positions_deg) if j.locked is None}
    with user_errors():
        try:
            pose = pose_document(name, arm, joints, description=description,
                                 source="simulator" if connection.is_simulator else "arm",
                                 saved_at=datetime.now(timezone.utc).replace(microsecond=0))
        except ValueError as exc:
            fail(str(exc))
        path.parent.mkdir(parents=True, exist_ok=True)
        save_pose(path, pose)
    typer.echo(f"saved {path}: " + ", ".join(f"{k} {v:g}" for k, v in pose.joints_deg.items()))
