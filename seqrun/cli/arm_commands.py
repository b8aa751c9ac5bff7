"""``seqrun status``, ``seqrun halt``, ``seqrun reset``: the arm outside a sequence.

With no interface configured these talk to a fresh simulator (they say so); point them at
a shared simulator with ``-i socketcand`` (``seqrun sim serve``) or at the real bus.
``halt`` and ``reset`` succeed only when every module confirms (its state read back by the
arm's driver); ``status --watch`` survives lost answers (shown as stale).
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
from seqrun.cli.common import (EXIT_FAULT, ArmOption, BitrateOption, BusKwargsOption,
                               ChannelOption, InterfaceOption, ResponseTimeoutOption,
                               SimOption, connect, fail, load_arm_file, user_errors)
from seqrun.defaults import DEFAULT_ARM
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
    arm_file: ArmOption = DEFAULT_ARM, interface: InterfaceOption = None,
    channel: ChannelOption = None, bitrate: BitrateOption = None,
    bus_kwargs: BusKwargsOption = None, sim: SimOption = False,
    response_timeout_ms: ResponseTimeoutOption = None,
) -> None:
    """Joints, state flags and end-effector pose (reads only; nothing moves).

    With --watch a lost answer does not end the watch: the joint shows its last value,
    marked stale, and the next refresh asks again.
    """
    from rich.live import Live

    from seqrun.cli.bus_owner import (OwnerDidNotAnswer, StatusSource, owner_text,
                                      warn_once_in)
    from seqrun.cli.output import make_console

    with user_errors():
        arm = load_arm_file(arm_file)
        key = _bus_key(arm, interface, channel, bitrate, bus_kwargs, sim, response_timeout_ms)
    console = make_console()
    warn = warn_once_in(5.0, lambda text: typer.echo(f"warning: {text}", err=True))
    # Reads only: a run holding the bus is asked over its socket, else the bus is read
    # (seqrun/cli/bus_owner.py).
    source = StatusSource(arm, key, lambda: connect(
        arm, interface, channel, bitrate, bus_kwargs, sim,
        response_timeout_ms=response_timeout_ms, claim=False), warn)
    try:
        with user_errors():
            status = source.read(tolerate_loss=watch)
        if not as_json:
            if source.holder is not None:
                console.print(f"from {owner_text(source.holder)}: "
                              f"{status.get('bus') or ''}", style="bold", highlight=False,
                              markup=False)
            else:
                console.print(source.description, style="bold", highlight=False,
                              markup=False)
                console.print(source.zero_text, highlight=False, markup=False)
        if not watch:
            if as_json:
                typer.echo(json.dumps(_with_origin(status, source)))
            else:
                console.print(status_table(status, _title(arm, source, status)))
            return
        if as_json:
            _watch_json(source, status, period, count, warn)
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


def _bus_key(arm, interface, channel, bitrate, bus_kwargs, sim, response_timeout_ms):
    """The claim key of the bus these options name (None: the simulator); checks the
    options first, as connecting would."""
    from seqrun.service.connection import parse_bus_kwargs, response_timeout_s, shared_bus

    response_timeout_s(arm, response_timeout_ms)
    return shared_bus(interface=interface, channel=channel, bitrate=bitrate,
                      bus_kwargs=parse_bus_kwargs(bus_kwargs or []), force_sim=sim)


def _title(arm, source, status: dict) -> str:
    if source.holder is None:
        return arm.name
    step = status.get("step") or {}
    where = f", step {step['step']}: {step['label']}" if step.get("step") else ""
    return f"{arm.name} (from seqrun pid {source.holder['pid']}{where})"


def _with_origin(status: dict, source) -> dict:
    """A reading from the bus owner says so (``"from": {"pid", "command"}``)."""
    if source.holder is None:
        return status
    return {**status, "from": {"pid": source.holder["pid"],
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


def _watch_json(source, status: dict, period: float, count: int | None, warn) -> None:
    """JSON lines: one object per refresh, flushed at once (for a pipe), with its time."""
    for index in _refreshes(period, count):
        if index:
            status = _next_reading(source, status, warn)
        typer.echo(json.dumps({"time": round(time.time(), 3), **_with_origin(status, source)}))
        sys.stdout.flush()


def _broadcast(what: str, arm_file, interface, channel, bitrate, bus_kwargs, sim,
               response_timeout_ms) -> None:
    """Broadcast Halt or Reset, then confirm it module by module (exit 3 if not all do)."""
    from seqrun.service.arm_access import broadcast_and_confirm

    with user_errors():
        arm = load_arm_file(arm_file)
        connection, driver = connect(arm, interface, channel, bitrate, bus_kwargs, sim,
                                     response_timeout_ms=response_timeout_ms)
    try:
        result = broadcast_and_confirm(driver, what)
    finally:
        driver.close()
        connection.close()
    if not result.sent:
        fail(f"{what} not sent: {result.error}", EXIT_FAULT)
    if not result.confirmed:
        error = f"; {result.error}" if result.error else ""
        fail(f"{what} broadcast sent, but not confirmed by {result.describe_unconfirmed()} "
             f"after {result.attempts} attempts ({connection.description}{error})", EXIT_FAULT)
    typer.echo(f"{what.capitalize()} confirmed by modules "
               f"{', '.join(map(str, sorted(result.states)))} ({connection.description})")


@app.command("halt")
def halt_command(arm_file: ArmOption = DEFAULT_ARM, interface: InterfaceOption = None,
                 channel: ChannelOption = None, bitrate: BitrateOption = None,
                 bus_kwargs: BusKwargsOption = None, sim: SimOption = False,
                 response_timeout_ms: ResponseTimeoutOption = None) -> None:
    """Broadcast Halt: every module stops at once and refuses motion until Reset.
    Confirmed by reading every module's state back (HALTED); exit 3 naming the modules
    that did not confirm. While another seqrun holds the bus (a run), the Halt goes
    straight to the bus all the same, and that seqrun confirms it."""
    with user_errors():
        arm = load_arm_file(arm_file)
        key = _bus_key(arm, interface, channel, bitrate, bus_kwargs, sim, response_timeout_ms)
    if key is None:   # the simulator of this process: nobody else's bus
        _broadcast("halt", arm_file, interface, channel, bitrate, bus_kwargs, sim,
                   response_timeout_ms)
        return
    _halt_shared_bus(arm, key, lambda: connect(
        arm, interface, channel, bitrate, bus_kwargs, sim,
        response_timeout_ms=response_timeout_ms, claim=False))


def _halt_shared_bus(arm, key: tuple[str, str], open_bus) -> None:
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
def reset_command(arm_file: ArmOption = DEFAULT_ARM, interface: InterfaceOption = None,
                  channel: ChannelOption = None, bitrate: BitrateOption = None,
                  bus_kwargs: BusKwargsOption = None, sim: SimOption = False,
                  response_timeout_ms: ResponseTimeoutOption = None) -> None:
    """Broadcast Reset: clears ERROR/HALTED (motion still needs Home). Confirmed by reading
    every module's state back (no ERROR, no HALTED); exit 3 naming the modules that did
    not confirm."""
    _broadcast("reset", arm_file, interface, channel, bitrate, bus_kwargs, sim,
               response_timeout_ms)
