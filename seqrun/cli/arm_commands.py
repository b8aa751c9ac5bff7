"""``seqrun status``, ``seqrun halt``, ``seqrun reset``: the arm outside a sequence.

They talk to the bus of the arm context (seqrun/service/arm_context.py: the command
line, else the campaign's ``[bus]``, else python-can's configuration). With no bus
configured they never act on a private simulator of their own: ``status`` and ``halt`` act
through the seqrun run or console live on this machine (its control socket), and with
nothing live there is no arm (exit 2); ``--sim`` asks for a private simulator. ``halt`` and
``reset`` succeed only when every module confirms (its state read back by the arm's
driver); ``status --watch`` survives lost answers (shown as stale). The first line says
which arm and bus.
"""

from __future__ import annotations

import itertools
import json
import sys
import time
from collections.abc import Iterator
from typing import TYPE_CHECKING, Annotated, Optional

import typer

from seqrun.cli.app import app
from seqrun.cli.common import (EXIT_FAULT, ArmFileOption, BitrateOption, BusKwargsOption,
                               CampaignOption, ChannelOption, InterfaceOption,
                               ResponseTimeoutOption, SimOption, fail, user_errors)
from seqrun.errors import BusError

if TYPE_CHECKING:  # imported where used: `seqrun --help` stays light
    from rich.table import Table



def _number(value: float | None) -> str:
    from seqrun.cli.output import fixed

    return "-" if value is None else fixed(value, 3)  # never -0.000


def status_table(status: dict, title: str) -> Table:
    from rich.table import Table

    table = Table(title=title)
    for col in ("joint", "module", "position °", "velocity °/s", "state"):
        table.add_column(col)
    for j in status["joints"]:
        stale = j.get("stale", False)
        state = j["state"] or "-"
        table.add_row(j["joint"], str(j["module"]), _number(j["position_deg"]),
                      _number(j["velocity_deg_s"]),
                      f"{state} (stale: no answer)" if stale else state,
                      style="red" if j["fault"] else ("dim" if stale else None))
    ee = status["end_effector"]
    table.caption = ("end-effector unknown (no answer yet)" if ee is None else
                     f"end-effector {ee['position_mm']} mm, roll/pitch/yaw {ee['rpy_deg']} °")
    return table


@app.command("status")
def status_command(
    watch: Annotated[bool, typer.Option("--watch", help="Refresh until Ctrl-C.")] = False,
    as_json: Annotated[bool, typer.Option(
        "--json", help="Machine-readable output (with --watch: one JSON object per line, "
                       "per refresh).")] = False,
    period: Annotated[float, typer.Option(
        "--period", help="Refresh period with --watch, s.")] = 0.2,
    count: Annotated[Optional[int], typer.Option(
        "--count", min=1, help="With --watch: stop after this many refreshes.")] = None,
    pid: PidOption = None,
    arm_file: ArmFileOption = None, project_dir: CampaignOption = None,
    interface: InterfaceOption = None,
    channel: ChannelOption = None, bitrate: BitrateOption = None,
    bus_kwargs: BusKwargsOption = None, sim: SimOption = False,
    response_timeout_ms: ResponseTimeoutOption = None,
    arm_id: ArmIdOption = None,
) -> None:
    """Joints, state flags and end-effector pose (reads only; nothing moves).

    With --watch a lost answer does not end the watch: the joint shows its last value,
    marked stale, and the next refresh asks again. With no bus configured: the seqrun run
    or console live on this machine (--pid to pick one), else exit 2. In a campaign with
    several arms: every arm, one table each (--arm-id ID: that one; --watch: one arm).
    """
    with user_errors():
        ids = arm_ids_of(arm_id, project_dir, interface, channel, arm_file)
    if len(ids) > 1 and watch:
        fail(f"--watch follows one arm: name it with --arm-id ({', '.join(map(str, ids))})")
    each_arm(ids, lambda one: _status_of(
        one, watch, as_json, period, count, pid, arm_file, project_dir, interface, channel,
        bitrate, bus_kwargs, sim, response_timeout_ms), failed="status not read")


def _status_of(arm_id, watch, as_json, period, count, pid, arm_file, project_dir, interface,
               channel, bitrate, bus_kwargs, sim, response_timeout_ms) -> None:
    from rich.live import Live

    from seqrun.cli.bus_owner import (OwnerDidNotAnswer, StatusSource, live_targets,
                                      owner_text, warn_once_in)
    from seqrun.cli.output import make_console

    with user_errors():
        context = command_context(arm_file, project_dir, interface, channel, bitrate, bus_kwargs,
                           sim, response_timeout_ms, arm_id)
        arm = context.arm
        through = live_targets(context, "status", pid)
    console = make_console()
    warn = warn_once_in(5.0, lambda text: typer.echo(f"warning: {text}", err=True))
    # Reads only: a run holding the bus is asked over its socket, else the bus is read
    # (seqrun/cli/bus_owner.py).
    source = StatusSource(arm, context.bus.key,
                          lambda: context.open_arm(claim=False), warn,
                          live=through[0] if through else None)
    try:
        with user_errors():
            status = source.read(tolerate_loss=watch)
        if not as_json:
            if source.holder is not None:
                console.print(f"{context.arm_text()} via {owner_text(source.holder)} on "
                              f"{status.get('bus') or ''}", style="bold", highlight=False,
                              markup=False, soft_wrap=True)
            else:
                console.print(context.headline(source.connection), style="bold",
                              highlight=False, markup=False, soft_wrap=True)
                console.print(source.zero_text, highlight=False, markup=False)
        if not watch:
            if as_json:
                typer.echo(json.dumps(_with_origin(status, source, arm_id)))
            else:
                console.print(status_table(status, _title(arm, source, status)))
            return
        if as_json:
            _watch_json(source, status, period, count, warn, arm_id)
            return
        if not console.is_terminal:  # a file or a pipe: one whole line per refresh
            from seqrun.cli.status_line import status_line

            for index in _refreshes(period, count):
                if index:
                    status = _next_reading(source, status, warn)
                typer.echo(status_line(status))
                sys.stdout.flush()
            return
        # No auto-refresh thread: drawing the table between reads, never during one, keeps
        # it from holding the interpreter while acknowledges wait to be read.
        with Live(console=console, auto_refresh=False) as live:
            for index in _refreshes(period, count):
                if index:
                    status = _next_reading(source, status, warn)
                live.update(status_table(status, _title(arm, source, status)), refresh=True)
    except KeyboardInterrupt:
        pass
    except (BusError, OwnerDidNotAnswer) as exc:
        console.print(f"error: {exc}", style="red", highlight=False, markup=False)
        raise typer.Exit(EXIT_FAULT) from None
    finally:
        source.close()


#: ``--arm-id ID`` (repeatable): in a campaign with several arms ([arms.ID]), which ones
#: (default: every arm of the campaign).
ArmIdOption = Annotated[Optional[list[str]], typer.Option(
    "--arm-id", metavar="ID", help="In a campaign with several arms: this arm (repeatable; "
                                   "default every arm).")]

PidOption = Annotated[Optional[int], typer.Option(
    "--pid", metavar="PID", help="With no bus given: the live seqrun run or console to ask "
                                 "(when several are live on this machine).")]


def command_context(arm_file, project_dir, interface, channel, bitrate, bus_kwargs, sim,
             response_timeout_ms, arm_id: str | None = None):
    """The arm context of these options (seqrun/service/arm_context.py); checks the
    response timeout first, as connecting would."""
    from seqrun.service.arm_context import resolve_context
    from seqrun.service.connection import response_timeout_s

    context = resolve_context(project_dir=project_dir, arm_file=arm_file,
                              interface=interface, channel=channel, bitrate=bitrate,
                              bus_kwargs=bus_kwargs or [], sim=sim,
                              response_timeout_ms=response_timeout_ms, arm_id=arm_id)
    response_timeout_s(context.arm, response_timeout_ms)
    return context


def arm_ids_of(arm_ids, project_dir, interface=None, channel=None,
             arm_file=None) -> list[str | None]:
    """The arms a command acts on: ``--arm-id`` (checked), else every arm of a campaign
    with several, else the one arm (None). One bus or arm file on the command line for
    several arms: refused (each has its own)."""
    from seqrun.service.arm_context import resolve_contexts

    contexts = resolve_contexts(arm_ids=arm_ids or None, project_dir=project_dir,
                                interface=interface, channel=channel, arm_file=arm_file)
    return [c.arm_id for c in contexts]


def each_arm(ids: list[str | None], act, *, failed: str = "not confirmed") -> None:
    """``act(arm_id)`` for every arm; with several, one arm's failure (its own ``error:``
    line) does not keep the next from being acted on; the exit code is the worst and the
    last line names the arms that failed (``failed``: what went wrong for them, e.g. a
    Halt "not confirmed", a status "not read")."""
    if len(ids) == 1:
        act(ids[0])
        return
    failures: list[tuple[str, int]] = []
    for arm_id in ids:
        try:
            act(arm_id)
        except typer.Exit as exc:
            if exc.exit_code:
                failures.append((str(arm_id), exc.exit_code))
    if failures:
        fail(f"{failed} for arm{'s' * (len(failures) > 1)} "
             f"{', '.join(a for a, _ in failures)} (every arm was asked)",
             max(code for _, code in failures))


def _title(arm, source, status: dict) -> str:
    if source.holder is None:
        return arm.name
    step = status.get("step") or {}
    where = f", step {step['step']}: {step['label']}" if step.get("step") else ""
    return f"{arm.name} (from seqrun pid {source.holder['pid']}{where})"


def _with_origin(status: dict, source, arm_id: str | None) -> dict:
    """A reading as ``status --json`` writes it: with its arm's id (``"arm"``: the id in a
    campaign of several arms, else None), and, when it comes from the bus owner, saying so
    (``"from": {"pid", "command"}``)."""
    line = {"arm": arm_id, **status}
    if source.holder is None:
        return line
    return {**line, "from": {"pid": source.holder["pid"],
                             "command": source.holder["command"]}}


def _next_reading(source, previous: dict, warn) -> dict:
    """A watch's next reading; an owner that does not answer, or a bus held by one that
    serves no socket, is a warning: the previous values stay, marked stale."""
    from seqrun.cli.bus_owner import OwnerDidNotAnswer
    from seqrun.errors import Refused

    try:
        return source.read(previous, tolerate_loss=True)
    except (OwnerDidNotAnswer, Refused) as exc:
        warn(str(exc))
        return {**previous, "joints": [{**j, "stale": True} for j in previous["joints"]]}


def _refreshes(period: float, count: int | None) -> Iterator[int]:
    """Yields ``count`` times (None: forever), ``period`` seconds apart."""
    for index in itertools.count() if count is None else range(count):
        if index:
            time.sleep(period)
        yield index


def _watch_json(source, status: dict, period: float, count: int | None, warn,
                arm_id: str | None) -> None:
    """JSON lines: one object per refresh, flushed at once (for a pipe), with its time."""
    for index in _refreshes(period, count):
        if index:
            status = _next_reading(source, status, warn)
        typer.echo(json.dumps({"time": round(time.time(), 3),
                               **_with_origin(status, source, arm_id)}))
        sys.stdout.flush()


def _broadcast(what: str, context) -> None:
    """Broadcast Halt or Reset, then confirm it module by module (exit 3 if not all do)."""
    from seqrun.cli.confirmation import confirmed_or_exit
    from seqrun.service.arm_access import broadcast_and_confirm

    with user_errors():
        connection, driver = context.open_arm()
    typer.echo(context.headline(connection))
    try:
        result = broadcast_and_confirm(driver, what)
    finally:
        driver.close()
        connection.close()
    confirmed_or_exit(result, connection.description, what=what, sent_as="broadcast sent",
                      unconfirmed_after=f" after {result.attempts} attempts")


@app.command("halt")
def halt_command(arm_file: ArmFileOption = None, project_dir: CampaignOption = None,
                 interface: InterfaceOption = None,
                 channel: ChannelOption = None, bitrate: BitrateOption = None,
                 bus_kwargs: BusKwargsOption = None, sim: SimOption = False,
                 response_timeout_ms: ResponseTimeoutOption = None,
                 pid: PidOption = None, arm_id: ArmIdOption = None) -> None:
    """Broadcast Halt: every module stops at once and refuses motion until Reset.
    Confirmed by reading every module's state back (HALTED); exit 3 naming the modules
    that did not confirm. While another seqrun holds the bus (a run), the Halt goes
    straight to the bus all the same, and that seqrun confirms it. With no bus configured:
    the seqrun runs and consoles live on this machine are halted through their control
    sockets; with none live, exit 2 (there is no arm to halt). In a campaign with several
    arms every arm is halted and confirms, one after the other (--arm-id ID: that one); one
    arm that does not confirm does not keep the next from being halted (exit 3)."""
    with user_errors():
        ids = arm_ids_of(arm_id, project_dir, interface, channel, arm_file)
    each_arm(ids, lambda one: _halt_arm(one, arm_file, project_dir, interface, channel,
                                         bitrate, bus_kwargs, sim, response_timeout_ms, pid))


def _halt_arm(arm_id, arm_file, project_dir, interface, channel, bitrate, bus_kwargs, sim,
              response_timeout_ms, pid) -> None:
    from seqrun.cli.bus_owner import live_targets

    with user_errors():
        context = command_context(arm_file, project_dir, interface, channel, bitrate, bus_kwargs,
                           sim, response_timeout_ms, arm_id)
        live = live_targets(context, "halt", pid)
    if live:
        _halt_through(context, live)
        return
    key = context.bus.key
    if key is None:   # the simulator of this process, asked for with --sim
        _broadcast("halt", context)
        return
    _halt_shared_bus(context, key, lambda: context.open_arm(claim=False))


def _halt_through(context, live: list) -> None:
    """Halt the live runs/consoles found with no bus given, each through its control
    socket; each confirms by reading its modules back. Exit 3 unless every one did."""
    import os

    from seqrun.cli.bus_owner import holder_bus, owner_text
    from seqrun.service.control_socket import ask_holder

    failed = []
    for holder in live:
        who = owner_text(holder.as_dict())
        typer.echo(f"{context.arm_text()} via {who} on {holder_bus(holder)}")
        reply = ask_holder(holder, "halt",
                           reason=f"seqrun halt from another process (pid {os.getpid()})")
        halt = (reply or {}).get("halt") or {}
        if reply is not None and reply.get("ok") and halt.get("confirmed"):
            typer.echo(f"Halt confirmed by modules "
                       f"{', '.join(map(str, halt['modules_confirmed']))}, read back by {who}")
            continue
        why = ("it has ended" if reply is None else
               halt.get("message") or halt.get("error") or reply.get("error"))
        failed.append(f"{who} did not confirm the Halt: {why}")
    if failed:
        fail("; ".join(failed), EXIT_FAULT)


def _halt_shared_bus(context, key: tuple[str, str], open_bus) -> None:
    """Halt broadcast first, unclaimed (it needs no answer: always safe, even beside a
    run); then the bus owner confirms, or, with no owner, this process claims the bus and
    confirms by reading the modules back."""
    import os

    from seqrun.service.arm_access import broadcast_and_confirm
    from seqrun.cli.bus_owner import owner_text
    from seqrun.errors import Refused
    from seqrun.service.bus_claim import claim_bus
    from seqrun.service.control_socket import ask_owner

    with user_errors():
        connection, driver = open_bus()
    typer.echo(context.headline(connection))
    try:
        try:
            driver.halt_now()
        except BusError as exc:
            fail(f"halt not sent: {exc}", EXIT_FAULT)
        reply = ask_owner(*key, "halt",
                          reason=f"seqrun halt from another process (pid {os.getpid()})")
        if reply is not None:
            who = owner_text(reply["holder"])
            halt = reply.get("halt") or {}
            if reply.get("ok") and halt.get("confirmed"):
                typer.echo(f"Halt confirmed by modules "
                           f"{', '.join(map(str, halt['modules_confirmed']))}, read back by "
                           f"{who} ({connection.description})")
                return
            fail(f"Halt broadcast sent, but {who} did not confirm it: "
                 f"{halt.get('message') or halt.get('error') or reply.get('error')}",
                 EXIT_FAULT)
        try:
            claim = claim_bus(*key, transient=True)
        except Refused as exc:
            fail(f"Halt broadcast sent, but not confirmed: {exc}", EXIT_FAULT)
        with claim:
            result = broadcast_and_confirm(driver, "halt")
    except BusError as exc:
        fail(f"halt broadcast sent, not confirmed: {exc}", EXIT_FAULT)
    finally:
        driver.close()
        connection.close()
    if not result.confirmed:
        fail(f"halt broadcast sent, but not confirmed by {result.describe_unconfirmed()} "
             f"after {result.attempts} attempts ({connection.description})", EXIT_FAULT)
    typer.echo(f"Halt confirmed by modules {', '.join(map(str, sorted(result.states)))} "
               f"({connection.description})")


@app.command("reset")
def reset_command(arm_file: ArmFileOption = None, project_dir: CampaignOption = None,
                  interface: InterfaceOption = None,
                  channel: ChannelOption = None, bitrate: BitrateOption = None,
                  bus_kwargs: BusKwargsOption = None, sim: SimOption = False,
                  response_timeout_ms: ResponseTimeoutOption = None,
                  arm_id: ArmIdOption = None) -> None:
    """Broadcast Reset: clears ERROR/HALTED (motion still needs Home). Confirmed by reading
    every module's state back (no ERROR, no HALTED); exit 3 naming the modules that did
    not confirm. With no bus configured: exit 2 (a live run or console resets its arm
    itself). In a campaign with several arms: every arm (--arm-id ID: that one)."""
    with user_errors():
        ids = arm_ids_of(arm_id, project_dir, interface, channel, arm_file)
    each_arm(ids, lambda one: _reset_arm(one, arm_file, project_dir, interface, channel,
                                          bitrate, bus_kwargs, sim, response_timeout_ms))


def _reset_arm(arm_id, arm_file, project_dir, interface, channel, bitrate, bus_kwargs, sim,
               response_timeout_ms) -> None:
    from seqrun.cli.bus_owner import live_targets

    with user_errors():
        context = command_context(arm_file, project_dir, interface, channel, bitrate, bus_kwargs,
                           sim, response_timeout_ms, arm_id)
        live_targets(context, "reset")
    _broadcast("reset", context)
