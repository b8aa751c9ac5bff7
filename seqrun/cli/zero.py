"""``seqrun zero set POSE`` / ``seqrun zero set --deg Q1 ... Q7`` / ``seqrun zero show``, and
the zero check at the start of a run.

    seqrun zero show -i socketcan -c can0          # this arm's record and the zero in use
    seqrun zero show                               # every arm recorded on this machine
    seqrun zero set totem -i socketcan -c can0     # after a sudden power loss in Totem
    seqrun zero set --deg 12 -35 0 80 0 40 0 -i socketcan -c can0   # ... anywhere else

The record belongs to the physical arm: its modules' serial numbers, read over the bus
(the campaign's, python-can's configuration, or -i/-c), say which one (see
:mod:`seqrun.service.zero`). The ``power_off`` step of ``sequences/shutdown.yaml`` writes
it at a normal shutdown.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Callable, Optional

import typer

from seqrun.cli.app import app
from seqrun.cli.common import (ArmFileOption, BitrateOption, BusKwargsOption, CampaignOption,
                               ChannelOption, EXIT_FAULT, InterfaceOption, OneArmOption, fail,
                               user_errors)
from seqrun.cli.questions import ask
from seqrun.errors import BusError, UserInputError
from seqrun.formatting import terminal_text
from seqrun.service.zero import (POSE_IN_DEGREES, ZeroInForce, ZeroNotConfirmed, ZeroStore,
                                 pose_title, zero_at_start)

#: ``zero set`` with no bus named: there is no arm to record.
NO_ARM_NAMED = ("no arm named: the built-in simulator takes its zero from its power-on pose "
                "(--power-on-at); name the arm's bus (-i/-c, the campaign's seqrun.toml or "
                "python-can's configuration)")

zero_app = typer.Typer(help="The zero reference: where the arm was powered off.",
                       no_args_is_help=True)
app.add_typer(zero_app, name="zero")


def _context(arm_file: Optional[Path], project_dir: Optional[Path], interface, channel,
             bitrate, bus_kwargs, arm_id: str | None = None):
    """The arm context (seqrun/service/arm_context.py): the arm file, and the arm's bus
    (the options, else the campaign's, else python-can's configuration)."""
    from seqrun.service.arm_context import resolve_context

    return resolve_context(project_dir=project_dir, arm_file=arm_file, interface=interface,
                           channel=channel, bitrate=bitrate, bus_kwargs=bus_kwargs or (),
                           arm_id=arm_id)


def _arm_store(arm, connection) -> tuple[ZeroStore, int | None]:
    """The connected arm's store (its identity read from the modules) and the
    power-session mark its modules hold; UserInputError on the built-in simulator, whose
    zero is its power-on pose."""
    from seqrun.service.arm_access import identity_and_session_mark

    if connection.is_simulator:
        raise UserInputError(NO_ARM_NAMED)
    identity, mark = identity_and_session_mark(connection, arm)
    return ZeroStore(identity), mark


def _in_force(store: ZeroStore, mark: int | None):
    """The zero confirmed at this power-on while the modules hold its mark, else None."""
    in_use = store.in_use
    if in_use is None or in_use.session_mark is None or in_use.session_mark != mark:
        return None
    return in_use


def _connected_store(context) -> tuple[ZeroStore, int | None]:
    """Open the context's bus (its first line said), and :func:`_arm_store` of the arm
    there; the bus is closed again. Exit 3 when the modules do not answer."""
    connection = context.open_connection(transient=True)
    typer.echo(context.headline(connection))
    try:
        return _arm_store(context.arm, connection)
    except BusError as exc:
        fail(f"cannot read the modules' serial numbers: {exc}", 3)
    finally:
        connection.close()


def _list_machine_records() -> None:
    import json

    from seqrun.service.zero import ZeroRecord, state_dir

    folder = state_dir() / "arms"
    files = sorted(folder.glob("arm-*.json")) if folder.is_dir() else []
    typer.echo(f"arms recorded on this machine ({folder}): {len(files) or 'none'}")
    for path in files:
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
            serials = ", ".join(f"{m}:{s}" for m, s in data["arm"]["serials"].items())
            record = ZeroRecord.from_dict(data.get("record"))
        except (OSError, ValueError, KeyError, TypeError, AttributeError):
            typer.echo(f"  {path.name}: unreadable")
            continue
        name = data["arm"].get("name") or "arm"
        typer.echo(terminal_text(f"  {name} (serials {serials})"))
        typer.echo("    record " + (terminal_text(record.describe()) if record else "none"))
    typer.echo("name the arm's bus (-i/-c) to see whether its record can be used")


@zero_app.command("show")
def show_command(
    project_dir: CampaignOption = None,
    arm_file: ArmFileOption = None,
    interface: InterfaceOption = None,
    channel: ChannelOption = None,
    bitrate: BitrateOption = None,
    bus_kwargs: BusKwargsOption = None,
    arm_id: OneArmOption = None,
) -> None:
    """The connected arm's zero reference: where it was last powered off, and the zero in
    use since the last power-on. Without a bus: every arm recorded on this machine."""
    with user_errors():
        context = _context(arm_file, project_dir, interface, channel, bitrate, bus_kwargs,
                           arm_id)
        arm = context.arm
        if context.bus.is_simulator:  # no arm named: what this machine has recorded
            _list_machine_records()
            return
        store, mark = _connected_store(context)
        record, in_use = store.record, _in_force(store, mark)
    typer.echo(f"arm      {arm.name} ({store.identity.describe()})")
    typer.echo(f"file     {store.path}")
    typer.echo("record   " + (terminal_text(record.describe()) if record else
                              f"none (set one with '{store.set_command}')"))
    typer.echo("in use   " + (terminal_text(in_use.record.describe()) if in_use else
                              "none confirmed since the modules powered on"))
    typer.echo("poses    " + ", ".join(arm.power_off_poses or ["(the arm names none)"]))


@zero_app.command("set")
def set_command(
    pose: Annotated[Optional[str], typer.Argument(
        help="The power-off pose the arm stands in (power_off_poses of the arm file).")]
    = None,
    degrees: Annotated[Optional[list[float]], typer.Option(
        "--deg", metavar="Q1 ... Qn", help="Instead of POSE: the joint angles (user degrees, "
        "every joint in order) the arm stands in, e.g. after a power loss mid-move.")] = None,
    yes: Annotated[bool, typer.Option(
        "--yes", "-y", help="Do not ask (the pose is the one named on this command line).")]
    = False,
    project_dir: CampaignOption = None,
    arm_file: ArmFileOption = None,
    interface: InterfaceOption = None,
    channel: ChannelOption = None,
    bitrate: BitrateOption = None,
    bus_kwargs: BusKwargsOption = None,
    arm_id: OneArmOption = None,
) -> None:
    """Record where the connected arm was powered off (after a sudden power loss); asks
    first. The arm is named by its modules' serial numbers, read over its bus."""
    import math

    with user_errors():
        context = _context(arm_file, project_dir, interface, channel, bitrate, bus_kwargs,
                           arm_id)
        arm = context.arm
        if (pose is None) == (degrees is None):
            raise UserInputError("give the power-off pose (POSE) or the joint angles "
                                 "(--deg Q1 ... Qn), one of them")
        joints: dict[str, float] | None = None
        if degrees is not None:
            if len(degrees) != arm.dof:
                raise UserInputError(f"--deg: the arm has {arm.dof} joints "
                                     f"({', '.join(arm.joint_names)}), got {len(degrees)} "
                                     "angles")
            if not all(math.isfinite(q) for q in degrees):
                raise UserInputError("--deg: angles must be finite numbers")
            outside = [f"{j.name} {q:g}° (limits {j.limits_deg[0]:g} .. {j.limits_deg[1]:g}°)"
                       for j, q in zip(arm.joints, degrees)
                       if not j.limits_deg[0] <= q <= j.limits_deg[1]]
            if outside:
                raise UserInputError(f"--deg: outside the joint limits of arm '{arm.name}': "
                                     f"{', '.join(outside)}; nothing recorded")
            joints = dict(zip(arm.joint_names, degrees))
            name, title = POSE_IN_DEGREES, "the pose"
        else:
            assert pose is not None
            arm.power_off_pose(pose)
            name = pose if pose in arm.power_off_poses else pose.lower()
            joints, title = arm.power_off_joints_deg(name), pose_title(name)
        stands = joints
        if context.bus.is_simulator:
            raise UserInputError(NO_ARM_NAMED)
        store, mark = _connected_store(context)
        try:
            in_use = _in_force(store, mark)
        except UserInputError:  # an untrusted file: this record replaces it
            in_use = None
    angles = ", ".join(f"{n} {v:g}°" for n, v in stands.items())
    question = (f"Record that '{arm.name}' ({store.identity.describe()}) was powered off in "
                f"{title} ({angles})? The next power-on takes its zero there.")
    if yes:
        typer.echo(f"{question} yes (--yes)")
    elif not ask(question):  # (an empty stdin is a no, as in every question)
        fail("nothing recorded", 130)
    with user_errors():
        record = store.set_record(name, by="seqrun zero set", joints_deg=joints,
                                  arm_name=arm.name)
    typer.echo(f"zero reference recorded: {record.describe()} ({store.path})")
    if in_use is not None:
        typer.echo(f"note: the modules are still on: runs keep the zero confirmed at "
                   f"this power-on ({in_use.record.describe()}) until they are powered off; "
                   "the record is the zero of the next power-on")


def zero_at_run_start(connection, arm, ask: Callable[[str], bool],
                      show: Callable[[str], None], confirmed: str | None = None,
                      store: ZeroStore | None = None) -> ZeroInForce:
    """Decide the zero reference of a run, show it, and on real hardware after a power-on
    have the operator confirm the pose before anything moves (``ask``, or ``confirmed``:
    ``--zero-confirmed POSE``; ``--yes`` never answers it). The record belongs to the arm,
    not to a campaign.

    Raises :class:`UserInputError` (no record, an untrusted file: nothing moves),
    :class:`BusError`, or ``typer.Exit(130)`` when the operator says the arm is not in that
    pose.
    """
    def shown(text: str) -> None:   # the record's fields are a file's text
        show(terminal_text(text, lines=True))

    try:
        return zero_at_start(connection, arm, ask=ask, show=shown, confirmed=confirmed,
                             store=store)
    except ZeroNotConfirmed as exc:
        shown(str(exc))
        raise typer.Exit(130) from None


def zero_or_exit(connection, arm, ask: Callable[[str], bool], show: Callable[[str], None],
                 confirmed: str | None = None, arm_id: str | None = None) -> ZeroInForce:
    """:func:`zero_at_run_start` for a command: what it refuses is one line and the usage
    exit code, a bus that does not answer is one line and the fault exit code (a timeout
    is no usage error), ``arm ID:`` first when a campaign has several arms."""
    where = f"arm {arm_id}: " if arm_id else ""
    with user_errors():
        try:
            return zero_at_run_start(connection, arm, ask, show, confirmed=confirmed)
        except BusError as exc:
            fail(f"{where}cannot read the modules' state: {exc}", EXIT_FAULT)
        except UserInputError as exc:   # (a --zero-confirmed of another arm's pose, ...)
            fail(f"{where}{exc}")


ZeroConfirmedOption = Annotated[Optional[str], typer.Option(
    "--zero-confirmed", metavar="POSE", help="Answer 'does the arm stand in POSE?' after a "
    "power-on without asking (POSE must be where the arm was recorded powered off).")]

def open_arm_at_zero(context, confirmed: str | None, arm_id: str | None = None, *,
                     to_stderr: bool = False):
    """For a command that moves without a session (home, limits set): open the context's
    bus, decide its zero as a run does (asked after a power-on, or ``confirmed``), open the
    arm's driver with it and check the arm's identity before anything moves
    (service/arm_identity.py). ``(connection, driver, zero)``; a refusal is one line and
    its exit code, the bus closed again. ``to_stderr``: what it says goes to stderr (the
    command's stdout is JSON)."""
    from seqrun.cli.questions import ask
    from seqrun.service.arm_identity import open_checked_driver
    from seqrun.service.connection import response_timeout_s

    where = f"arm {arm_id}: " if arm_id else ""
    connection = context.open_connection(transient=True)
    typer.echo(context.headline(connection), err=to_stderr)
    try:
        zero = zero_or_exit(connection, context.arm, lambda q: ask(where + q, False),
                            lambda text: typer.echo(where + text, err=to_stderr),
                            confirmed=confirmed, arm_id=arm_id)
        timeout = response_timeout_s(context.arm, context.response_timeout_ms)
        with user_errors():
            driver = open_checked_driver(connection, context.arm, zero, timeout)
    except BaseException:
        connection.close()
        raise
    return connection, driver, zero


def zero_for_reading(connection, arm, project=None):
    """The arm with the zero reference in force for reading positions (status, pose save):
    ``(arm, text)``; see :func:`seqrun.service.zero.zero_for_reading`."""
    from seqrun.service.zero import zero_for_reading as reading

    arm, text = reading(connection, arm)
    return arm, terminal_text(text, lines=True)   # the record's fields are a file's text


__all__ = ["zero_at_run_start", "zero_or_exit", "zero_for_reading", "open_arm_at_zero",
           "ZeroConfirmedOption", "BusError",
           "UserInputError"]
