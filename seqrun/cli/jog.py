"""``seqrun jog JOINT VELOCITY --for SECONDS``: one joint at a velocity for a short time.

The thesis GUI's velocity buttons from a terminal, made safe like the console's jog (it is
the same session jog, :mod:`seqrun.service.jog`): never open-ended (``--for`` at most
:data:`MAX_JOG_S`; Ctrl-C stops it at once with a controlled stop), kept short of the
joint's limits and the workspace guards, in velocity mode (FVEL, the modules' watchdog
armed: a terminal that dies stops the joint within the watchdog timeout) or position mode
(FRAMP). The arm must be homed (``seqrun run sequences/startup.yaml`` or the console's Arm
and Home); like ``seqrun status``, with no bus configured it needs ``--sim``. On a busy host
``--rt-priority N`` keeps the loop (and so the watchdog's refresh) on time, as for ``run``
and ``console`` (bench/bench_jog.py measures it).
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Annotated, Any, Optional

import typer

from seqrun.cli.app import app
from seqrun.cli.common import (EXIT_FAULT, ArmFileOption, BitrateOption, BusKwargsOption,
                               CampaignOption, ChannelOption, InterfaceOption, OneArmOption,
                               ResponseTimeoutOption, SimOption, fail, user_errors)
from seqrun.cli.realtime_option import RtPriorityOption, use_realtime
from seqrun.defaults import EXIT_OPERATOR_ABORT

#: The longest jog a command line may ask for (s): a jog is a nudge, not a move.
MAX_JOG_S = 5.0
#: How often the command renews the jog's deadman (s), well inside its 200 ms.
RENEW_S = 0.05


@app.command("jog", context_settings={"ignore_unknown_options": True})  # -8: a velocity
def jog_command(
    joint: Annotated[str, typer.Argument(help="The joint, e.g. j1.")],
    velocity: Annotated[float, typer.Argument(
        help="deg/s, signed (the direction); at most the joint's limit.")],
    seconds: Annotated[float, typer.Option(
        "--for", min=0.01, max=MAX_JOG_S, help=f"How long, s (at most {MAX_JOG_S:g}); "
                                                "then a controlled stop.")],
    position_mode: Annotated[bool, typer.Option(
        "--position-mode", help="Stream position setpoints (FRAMP) instead of velocities "
                                "(FVEL).")] = False,
    interface: InterfaceOption = None,
    channel: ChannelOption = None,
    bitrate: BitrateOption = None,
    bus_kwargs: BusKwargsOption = None,
    sim: SimOption = False,
    arm_file: ArmFileOption = None,
    project_dir: CampaignOption = None,
    response_timeout_ms: ResponseTimeoutOption = None,
    zero_confirmed: Annotated[Optional[str], typer.Option(
        "--zero-confirmed", metavar="POSE", help="Answer 'does the arm stand in POSE?' after "
        "a power-on without asking.")] = None,
    arm_id: OneArmOption = None,
    rt_priority: RtPriorityOption = None,
) -> None:
    """Jog one joint at a velocity for a short time (FVEL; Ctrl-C stops it). On a busy
    host give --rt-priority N: the modules' watchdog stops a joint whose refresh comes
    late."""
    import math

    from seqrun.cli.questions import ask
    from seqrun.cli.zero import zero_or_exit
    from seqrun.errors import Refused
    from seqrun.service.arm_context import resolve_context
    from seqrun.service.connection import response_timeout_s
    from seqrun.service.session import ArmSession

    with user_errors():
        if not math.isfinite(velocity) or velocity == 0:
            fail(f"jog: velocity {velocity:g} deg/s must be a number other than 0")
        context = resolve_context(project_dir=project_dir, arm_file=arm_file, log_dir=None,
                                  interface=interface, channel=channel, bitrate=bitrate,
                                  bus_kwargs=bus_kwargs or [], sim=sim,
                                  response_timeout_ms=response_timeout_ms, arm_id=arm_id)
        project, arm = context.project, context.arm
        context.refuse_private_simulator("jog")
        timeout = response_timeout_s(arm, response_timeout_ms)
        if rt_priority is not None and not use_realtime(rt_priority,
                                                        "the jog's other threads"):
            rt_priority = None  # (before any thread starts: they inherit the policy)
        connection = context.open_connection(live=True)
    typer.echo(context.headline(connection))
    session = None
    try:
        with user_errors():
            zero = zero_or_exit(connection, arm, lambda q: ask(q, False), typer.echo,
                                confirmed=zero_confirmed)
            runs = context.runs_dir
            session = ArmSession(zero.apply(arm), connection, project=project,
                                 log_root=runs if runs.is_absolute() else Path.cwd() / runs,
                                 zero=zero, response_timeout_s=timeout, status_hz=0,
                                 arm_id=context.arm_id, loop_priority=rt_priority)
            session.poll_status()
            mode = "position" if position_mode else "velocity"
            # This process takes control of its session for the jog, as every face does
            # through the desk; each renewal presents the desk's secret.
            control = session.control.join_and_take(
                f"cli-{os.getpid()}", f"seqrun jog (pid {os.getpid()})", "cli")

            def jog() -> Any:
                holder = session.control.require(control.secret, "jog")
                return session.jog(joint, math.copysign(1.0, velocity), mode=mode,
                                   by=holder.name)

            try:
                session.set_move_velocities({joint: abs(velocity)})
                activity = jog()
            except Refused as exc:
                fail(str(exc))
        typer.echo(f"jog {joint} at {velocity:+g} deg/s for {seconds:g} s ({mode} mode); "
                   "Ctrl-C stops it")
        end = time.monotonic() + seconds
        try:
            while time.monotonic() < end and not activity.done:
                jog()
                time.sleep(RENEW_S)
        except KeyboardInterrupt:
            session.jog_stop()
            typer.echo(f"jog {joint}: stopped by Ctrl-C (controlled stop)")
            raise typer.Exit(EXIT_OPERATOR_ABORT) from None
        except Refused:
            pass  # the jog ended by itself (its range's end, a fault): its result says
        result = session.jog_stop() or activity.wait(timeout=30.0)
        position = session.status().joints_deg.get(joint)
        where = f"; {joint} at {position:.2f}°" if position is not None else ""
        typer.echo(f"{result.message}{where}")
        if not result.ok:
            raise typer.Exit(result.exit_code or EXIT_FAULT)
    finally:
        if session is not None:
            session.close()
        connection.close()
