"""``seqrun zero set POSE`` / ``seqrun zero show``, and the zero check at the start of a run.

    seqrun zero show                      # the record and the zero in use
    seqrun zero set totem                 # after a sudden power loss with the arm in Totem

The record says where the arm was powered off (see :mod:`seqrun.service.zero`); the ``power_off``
step of ``sequences/shutdown.yaml`` writes it at a normal shutdown.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Callable, Optional

import typer

from seqrun.cli.app import app
from seqrun.cli.common import ArmFileOption, CampaignOption, fail, user_errors
from seqrun.cli.questions import ask
from seqrun.errors import BusError, UserInputError
from seqrun.service.zero import ZeroInForce, ZeroStore, pose_title, zero_for_run

zero_app = typer.Typer(help="The zero reference: where the arm was powered off.",
                       no_args_is_help=True)
app.add_typer(zero_app, name="zero")

def _arm_and_store(arm_file: Optional[Path], project_dir: Optional[Path]):
    from seqrun.service.arm_context import resolve_context

    context = resolve_context(project_dir=project_dir, arm_file=arm_file)
    return context.arm, context.zero_store()


@zero_app.command("show")
def show_command(
    project_dir: CampaignOption = None,
    arm_file: ArmFileOption = None,
) -> None:
    """Where the arm was last powered off, and the zero in use since the last power-on
    (outside a campaign: the per-arm state file)."""
    with user_errors():
        arm, store = _arm_and_store(arm_file, project_dir)
        record, in_use = store.record, store.in_use
    typer.echo(f"arm      {arm.name}")
    typer.echo(f"file     {store.path}")
    typer.echo("record   " + (record.describe(pose_title(record.pose)) if record else
                              "none (set one with 'seqrun zero set POSE')"))
    typer.echo("in use   " + (in_use.describe(pose_title(in_use.pose)) if in_use else
                              "none confirmed since a power-on"))
    typer.echo("poses    " + ", ".join(arm.power_off_poses or ["(the arm names none)"]))


@zero_app.command("set")
def set_command(
    pose: Annotated[str, typer.Argument(help="The power-off pose the arm stands in "
                                             "(power_off_poses of the arm file).")],
    yes: Annotated[bool, typer.Option("--yes", "-y", help="Do not ask.")] = False,
    project_dir: CampaignOption = None,
    arm_file: ArmFileOption = None,
) -> None:
    """Record where the arm was powered off (after a sudden power loss); asks first."""
    with user_errors():
        arm, store = _arm_and_store(arm_file, project_dir)
        arm.power_off_pose(pose)
    name = pose if pose in arm.power_off_poses else pose.lower()
    joints = ", ".join(f"{n} {v:g}°" for n, v in arm.power_off_joints_deg(name).items())
    question = (f"Record that '{arm.name}' was powered off in {pose_title(name)} ({joints})? "
                "The next power-on takes its zero there.")
    if yes:
        typer.echo(f"{question} yes (--yes)")
    elif not ask(question):  # (an empty stdin is a no, as in every question)
        fail("nothing recorded", 130)
    record = store.set_record(name, by="seqrun zero set")
    typer.echo(f"zero reference recorded: {record.describe(pose_title(name))} ({store.path})")


def zero_at_run_start(connection, arm, project, ask: Callable[[str], bool],
                      show: Callable[[str], None], *, store: ZeroStore | None = None
                      ) -> ZeroInForce:
    """Decide the zero reference of a run, show it, and on real hardware after a power-on
    ask the operator to confirm the pose before anything moves.

    Raises :class:`UserInputError` (no record: nothing moves), :class:`BusError`, or
    ``typer.Exit(130)`` when the operator says the arm is not in that pose.
    """
    from seqrun.service.arm_access import modules_homed

    store = store or ZeroStore.for_arm(arm.name, project)
    homed = False if connection.is_simulator else modules_homed(connection, arm)
    zero = zero_for_run(arm, store, homed=homed,
                        simulator_pose=connection.power_on_pose if connection.is_simulator
                        else None)
    show(zero.text)
    if zero.question is not None:
        if not ask(zero.question):
            show("Not started: the operator says the arm is not in the recorded power-off "
                 "pose. Nothing was sent. Record the pose it was really powered off in with "
                 "'seqrun zero set POSE' and run again.")
            raise typer.Exit(130)
        assert zero.record is not None  # a question is asked about a record
        store.set_in_use(zero.record)
    return zero


__all__ = ["zero_at_run_start", "BusError", "UserInputError"]


def zero_for_reading(connection, arm, project=None, *, store: ZeroStore | None = None):
    """The arm with the zero reference in force for reading positions (status, pose save):
    ``(arm, text)``. Never asks and never refuses (nothing moves); without a usable record
    the text says the positions use the arm file's offsets. ``store``: the arm context's
    (:meth:`~seqrun.service.arm_context.ArmContext.zero_store`)."""
    store = store or ZeroStore.for_arm(arm.name, project)
    try:
        from seqrun.service.arm_access import modules_homed

        homed = False if connection.is_simulator else modules_homed(connection, arm)
        zero = zero_for_run(arm, store, homed=homed,
                            simulator_pose=connection.power_on_pose if connection.is_simulator
                            else None)
    except (UserInputError, BusError) as exc:
        return arm, (f"zero: unknown ({exc}); positions use the arm file's offsets "
                     f"({arm.default_power_off or 'as written'})")
    text = zero.text + (" (not yet confirmed at this power-on)" if zero.question else "")
    return arm.with_zero_reference(zero.pose), text
