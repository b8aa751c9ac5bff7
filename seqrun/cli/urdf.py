"""``seqrun urdf``: the arm as a URDF document, for robot_state_publisher, RViz, Foxglove
and MoveIt (docs/ros2-node.md).

    seqrun urdf > lwa3.urdf
    seqrun urdf --arm-id B -o b.urdf

Its link names are the frames ``seqrun ros`` publishes (``lwa3/base``, ``lwa3/j1`` ...), its
joint names those of ``joint_states``; the document is :mod:`seqrun.arm.urdf`'s.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from seqrun.cli.app import app
from seqrun.cli.common import ArmOption, OneArmOption, load_arm_file, user_errors
from seqrun.defaults import DEFAULT_ARM


@app.command("urdf")
def urdf_command(
    output: Annotated[Optional[Path], typer.Option(
        "-o", "--output", metavar="FILE", help="Write the URDF to FILE (default: stdout).")]
    = None,
    arm_name: Annotated[Optional[str], typer.Option(
        "--arm-name", metavar="NAME",
        help="The prefix of the link names, NAME/base ... (default: as seqrun ros names the "
             "arm: the arm file's name, e.g. lwa3; with --arm-id, the arm's id).")] = None,
    arm_file: ArmOption = DEFAULT_ARM,
    arm_id: OneArmOption = None,
) -> None:
    """Write the arm as a URDF: links, joints with their limits (the locked joint fixed),
    the link and tool volumes as cylinders and spheres, the tools' TCP frames."""
    from seqrun.ros import ros_name
    from seqrun.service.kinematics import robot_description

    with user_errors():
        arm = load_arm_file(arm_file, arm_id)
        name = ros_name(arm_name or arm_id or Path(arm.source_file or arm.name).stem)
        text = robot_description(arm, f"{name}/")
        if output is None:
            typer.echo(text, nl=False)
            return
        output.write_text(text, encoding="utf-8")
    typer.echo(f"wrote {output}: the URDF of {arm.name}, links {name}/base ...", err=True)
