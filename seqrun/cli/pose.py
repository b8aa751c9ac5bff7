"""``seqrun pose list``, ``seqrun pose show NAME`` and ``seqrun pose save NAME``."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Optional

import typer

from seqrun.cli.app import pose_app
from seqrun.cli.common import (BitrateOption, BusKwargsOption, CampaignOption, ChannelOption,
                               InterfaceOption, OneArmOption, SimOption, fail,
                               EXIT_INVALID, ArmFileOption, PosesDirOption, user_errors)
from seqrun.defaults import DEFAULT_POSES_DIR
from seqrun.errors import UserInputError

if TYPE_CHECKING:
    from seqrun.arm.poses import PoseFile


def load_named_pose(name: str, poses_dir: Path) -> PoseFile:
    from seqrun.service.poses import find_named_pose

    return find_named_pose(name, poses_dir)


def _context(project_dir: Path | None = None, poses_dir: Path | None = None,
             arm_file: Path | None = None, arm_id: str | None = None, **bus):
    """The arm context of a pose command (seqrun/service/arm_context.py)."""
    from seqrun.service.arm_context import resolve_context

    return resolve_context(project_dir=project_dir, poses_dir=poses_dir, arm_file=arm_file,
                           arm_id=arm_id, **bus)


def format_numbers(values, decimals: int = 3) -> str:
    # Rounded first, then + 0.0: -0.0001 prints as 0.000, not -0.000.
    return "[" + ", ".join(f"{round(float(v), decimals) + 0.0:.{decimals}f}"
                           for v in values) + "]"


@pose_app.command("list")
def list_poses(poses_dir: PosesDirOption = DEFAULT_POSES_DIR,
               project_dir: CampaignOption = None) -> None:
    """List the pose files: name, source and description (a campaign's poses are every
    arm's)."""
    from seqrun.service.arm_context import campaign_folders
    from seqrun.service.poses import list_poses

    with user_errors():
        _, pose_path, _ = campaign_folders(project_dir=project_dir, poses_dir=poses_dir)
        poses = list_poses(pose_path)
        if not poses:
            raise UserInputError(f"no pose files in {poses_dir}")
        width = max(len(name) for name, *_ in poses)
        for name, _path, pose, error in poses:
            if pose is None:  # one broken file must not hide the others
                typer.echo(f"{name:<{width}}  (invalid: {error})")
                continue
            summary = pose.description.split(". ")[0]  # the first sentence; `show` has it all
            typer.echo(f"{name:<{width}}  {pose.source or '-':<9}  {summary}")


@pose_app.command("show")
def show_pose(
    name: Annotated[str, typer.Argument(help="Pose name (file poses/<name>.yaml).")],
    poses_dir: PosesDirOption = DEFAULT_POSES_DIR,
    arm_file: ArmFileOption = None,
    project_dir: CampaignOption = None,
    arm_id: OneArmOption = None,
) -> None:
    """Show a pose and check it against the arm (exit 1 if it has problems)."""
    from seqrun.service.poses import pose_findings

    with user_errors():
        context = _context(project_dir, poses_dir, arm_file, arm_id)
        pose = load_named_pose(name, context.pose_path)
        arm = context.arm
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
    findings = pose_findings(pose, arm)
    for problem, finding in findings:
        typer.echo(f"problem: {finding}" if problem else finding, err=True)
    if any(problem for problem, _ in findings):
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
    arm_file: ArmFileOption = None, project_dir: CampaignOption = None,
    interface: InterfaceOption = None,
    channel: ChannelOption = None, bitrate: BitrateOption = None,
    bus_kwargs: BusKwargsOption = None, sim: SimOption = False,
    arm_id: OneArmOption = None,
) -> None:
    """Read the arm's joints and write them as a pose file (with the FK pose and the time).

    Reads the arm on the configured bus; the built-in simulator only with --sim (its arm
    always starts at Park, so a pose saved from it is marked source: simulator).
    """
    from seqrun.errors import BusError
    from seqrun.service.poses import check_pose_name, save_measured_pose

    with user_errors():
        check_pose_name(name)  # before anything is opened
        context = _context(project_dir, poses_dir, arm_file, arm_id, interface=interface,
                           channel=channel, bitrate=bitrate, bus_kwargs=bus_kwargs or [],
                           sim=sim)
        arm = context.arm
        if output is None and poses_dir == DEFAULT_POSES_DIR and context.project.is_campaign:
            poses_dir = context.project.poses_dir   # the campaign's poses/, from anywhere in it
        path = output or (poses_dir / f"{name}.yaml")
        if path.exists() and not force:
            fail(f"{path} exists (use --force to overwrite)")
        if context.bus.defaulted_to_simulator:
            fail("no CAN interface configured: pose save reads the arm on a bus (-i/-c, the "
                 "campaign's [bus] or python-can's configuration); give --sim to read the "
                 "built-in simulator")
        connection, driver = context.open_arm()
    typer.secho(context.headline(connection), fg="yellow" if connection.is_simulator else None,
                bold=True, err=True)
    try:
        from seqrun.service.zero import confirmed_zero_for_reading

        # The zero of the arm context, confirmed at this power-on: angles measured against
        # an assumed zero would send every later move to this pose elsewhere.
        try:
            arm, zero_text = confirmed_zero_for_reading(connection, arm)
        except UserInputError as exc:
            fail(str(exc))
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
            pose = save_measured_pose(path, name, arm, joints,
                                      simulator=connection.is_simulator,
                                      description=description)
        except ValueError as exc:
            fail(str(exc))
    typer.echo(f"saved {path}: " + ", ".join(f"{k} {v:g}" for k, v in pose.joints_deg.items()))
