"""``seqrun console``: the operator console in the browser, on one arm session.

    seqrun console                      # simulator (no bus configured), http://127.0.0.1:8765/
    seqrun console -i socketcan -c can0 # the real arm
    seqrun console --host 0.0.0.0       # reachable from a tablet

A token is printed at start (in the URL): every request but STOP needs it.

The web stack (FastAPI, uvicorn) is imported only when the command runs.
"""

from __future__ import annotations

import signal
from pathlib import Path
from typing import Annotated, Any, Optional

import typer

from seqrun.cli.app import app
from seqrun.cli.arm_commands import ArmIdOption
from seqrun.cli.common import (ArmFileOption, BitrateOption, BusKwargsOption,
                               CampaignOption, ChannelOption, InterfaceOption,
                               ResponseTimeoutOption, SimOption, ZeroConfirmedPerArmOption,
                               fail, user_errors, zero_confirmed_of)
from seqrun.cli.foxglove_option import (FoxgloveOption, FoxgloveTypesOption, check_foxglove,
                                        start_foxglove)
from seqrun.cli.realtime_option import use_realtime
from seqrun.cli.questions import ask
from seqrun.defaults import EXIT_OPERATOR_ABORT


@app.command("console")
def console_command(
    interface: InterfaceOption = None,
    channel: ChannelOption = None,
    bitrate: BitrateOption = None,
    bus_kwargs: BusKwargsOption = None,
    sim: SimOption = False,
    port: Annotated[int, typer.Option("--port", help="TCP port (0: any free port).")] = 8765,
    host: Annotated[Optional[str], typer.Option(
        "--host", metavar="ADDR",
        help="Listen on ADDR instead of 127.0.0.1 (e.g. 0.0.0.0 for a tablet); every "
             "request but STOP needs the token printed at start, wherever it listens.")] = None,
    arm_file: ArmFileOption = None,
    project_dir: CampaignOption = None,
    log_dir: Annotated[Optional[Path], typer.Option(
        "--log-dir", metavar="DIR", help="Where run folders go (default: the project's runs/).")]
    = None,
    response_timeout_ms: ResponseTimeoutOption = None,
    rt_priority: Annotated[Optional[int], typer.Option(
        "--rt-priority", metavar="N", min=1, max=99,
        help="Run the control loop's thread with real-time scheduling (SCHED_FIFO priority "
             "N) and the console's other threads at SCHED_RR 1, below it (needs the right "
             "to, e.g. root or CAP_SYS_NICE). Keeps the 100 Hz loop on time beside busy "
             "browser tabs.")] = None,
    yes: Annotated[bool, typer.Option(
        "--yes", "-y", help="Kept for scripts; it does not answer the zero question "
                            "(--zero-confirmed POSE does).")] = False,
    zero_confirmed: ZeroConfirmedPerArmOption = None,
    foxglove: FoxgloveOption = None,
    foxglove_types: FoxgloveTypesOption = None,
    arm_id: ArmIdOption = None,
) -> None:
    """Serve the operator console (STOP, telemetry, 3D view, commands, sequences); in a
    campaign with several arms, every arm (--arm-id ID: those) in one page."""
    from seqrun.cli.zero import zero_or_exit
    from seqrun.service.arm_context import campaign_arm_ids, resolve_context
    from seqrun.service.campaigns import campaign_here
    from seqrun.service.connection import response_timeout_s

    with user_errors():
        if not 0 <= port <= 65535:
            fail(f"--port must lie in 0-65535, got {port}")
        check_foxglove(foxglove, foxglove_types)
        campaign_ids = campaign_arm_ids(campaign_here(project_dir))
        several = bool(campaign_ids)
        confirmed = zero_confirmed_of(zero_confirmed, list(campaign_ids) or [None])
        if several:
            refused = {"-i/--interface": interface, "-c/--channel": channel,
                       "-b/--bitrate": bitrate, "--bus-kwargs": bus_kwargs,
                       "--arm": arm_file}
            given = [name for name, value in refused.items() if value]
            if given:
                fail(f"{', '.join(given)}: not for a campaign with several arms (each arm's "
                     "arm file and bus are in seqrun.toml)")
        elif arm_id:
            resolve_context(project_dir=project_dir, arm_id=arm_id[0])  # says why
        if rt_priority is not None and not use_realtime(
                rt_priority, "the console's other threads"):
            rt_priority = None  # (before any thread starts: they inherit the policy)
    if several:
        _serve_arms(arm_id, project_dir=project_dir, sim=sim, port=port, host=host,
                    log_dir=log_dir, response_timeout_ms=response_timeout_ms,
                    rt_priority=rt_priority, confirmed=confirmed,
                    foxglove=(foxglove, foxglove_types))
        return
    with user_errors():
        # The arm context: the campaign here, its arm, its bus (seqrun/service/arm_context.py).
        context = resolve_context(project_dir=project_dir, arm_file=arm_file,
                                  log_dir=log_dir, interface=interface, channel=channel,
                                  bitrate=bitrate, bus_kwargs=bus_kwargs or [], sim=sim,
                                  response_timeout_ms=response_timeout_ms)
        project, arm = context.project, context.arm
        timeout = response_timeout_s(arm, response_timeout_ms)
        context.refuse_private_simulator("console")
        from seqrun.console.server import LOCALHOST, bind, is_loopback, url_of

        from seqrun.console.guard import new_token

        listen = host or LOCALHOST
        token = new_token()  # on 127.0.0.1 too: any local process could command the arm
        try:
            sock = bind(listen, port)  # before the bus: a port in use costs nothing
        except OSError as exc:
            fail(f"cannot listen on {listen}:{port}: {exc.strerror or exc}")
        connection = context.open_connection(live=True)
    typer.echo(context.headline(connection))
    try:
        zero = zero_or_exit(connection, arm, lambda q: ask(q, False), typer.echo,
                            confirmed=confirmed.get(None))
        arm = zero.apply(arm)
    except BaseException:
        sock.close()
        connection.close()
        raise
    runs = context.runs_dir
    runs = runs if runs.is_absolute() else Path.cwd() / runs

    from seqrun.console.app import create_app
    from seqrun.console.catalog import Catalog
    from seqrun.service.session import ArmSession

    # at real-time priority the arm file's can.watchdog.with_rt_priority arms the watchdog
    arm = arm.at_loop_priority(rt_priority is not None)
    session = ArmSession(arm, connection, project=project, log_root=runs, zero=zero,
                         response_timeout_s=timeout, loop_priority=rt_priority,
                         arm_path=context.arm_path, arm_id=context.arm_id)
    _serve_control_socket(connection, session)
    live_foxglove = None
    try:
        try:
            live_foxglove = start_foxglove(session, arm, foxglove, typer.echo,
                                           foxglove_types)
        except (OSError, RuntimeError) as exc:
            fail(f"--foxglove: the Foxglove server could not start ({exc})")
        application = create_app(session, Catalog(project, runs), arm, token=token,
                                 local_only=is_loopback(listen), start_checker=True)
        url = url_of(sock, listen, token)
        banner = "SIMULATOR" if connection.is_simulator else connection.description

        def started() -> None:
            typer.echo(f"seqrun console on {banner}: {url}")
            typer.echo(f"token (every request but STOP needs it; the URL carries it): {token}")
            typer.echo("Ctrl-C ends the console (any motion is stopped first).")

        _serve_until_ended(application, sock, started,
                           lambda why: session.halt(why).describe())
    finally:
        if live_foxglove is not None:
            live_foxglove.close()
        session.close()  # controlled stop of anything still moving, then the bus


def _serve_until_ended(application, sock, started, halt) -> None:
    """Serve until Ctrl-C (a controlled stop of anything moving, by the caller's close)
    or SIGTERM (``halt(reason)``: the Halt, its line)."""
    from seqrun.console.server import serve
    from seqrun.service.realtime import keep_long_lived_objects_out_of_collections

    keep_long_lived_objects_out_of_collections()  # (the session, the app: made by now)

    # uvicorn shuts down gracefully on SIGINT/SIGTERM (the pages are disconnected, their
    # motions stopped), then raises the signal again: Ctrl-C arrives here as
    # KeyboardInterrupt, SIGTERM through this handler. SIGTERM halts, as for a run.
    previous = signal.signal(signal.SIGTERM, _terminated)
    try:
        serve(application, sock, on_started=started)
    except KeyboardInterrupt:
        typer.echo("seqrun console: ended by Ctrl-C; anything still moving is stopped")
        raise typer.Exit(EXIT_OPERATOR_ABORT) from None
    except _Terminated:
        typer.echo(f"seqrun console: ended by SIGTERM; {halt('SIGTERM (seqrun console)')}")
        raise typer.Exit(EXIT_OPERATOR_ABORT) from None
    finally:
        signal.signal(signal.SIGTERM, previous)


def _serve_arms(arm_ids: list[str] | None, *, project_dir: Path | None, sim: bool,
                port: int, host: str | None, log_dir: Path | None,
                response_timeout_ms: float | None, rt_priority: int | None,
                confirmed: dict[str | None, str] | None = None,
                foxglove: tuple[int | None, Any] = (None, None)) -> None:
    """The console of several arms (docs/two-arms.md): each arm's bus opened and claimed
    and its zero decided as ``seqrun run`` of a two-arm sequence does, one arm session
    each, one page for all, one STOP for all; ``--foxglove``: one Foxglove server, every
    arm under its id (seqrun/foxglove/live.py), its commands through the same sessions and
    control desk as the page's."""
    from seqrun.cli.run_arms import decide_zeros, open_buses
    from seqrun.console.guard import new_token
    from seqrun.console.server import LOCALHOST, bind, is_loopback, url_of
    from seqrun.service.arm_context import resolve_contexts
    from seqrun.service.arms_console import ArmSessions
    from seqrun.service.connection import response_timeout_s

    with user_errors():
        contexts = {str(c.arm_id): c for c in resolve_contexts(
            arm_ids=arm_ids or None, project_dir=project_dir, sim=sim,
            response_timeout_ms=response_timeout_ms)}
        for context in contexts.values():
            context.refuse_private_simulator("console")
            response_timeout_s(context.arm, response_timeout_ms)  # before any bus
        listen = host or LOCALHOST
        token = new_token()
        try:
            sock = bind(listen, port)  # before the buses: a port in use costs nothing
        except OSError as exc:
            fail(f"cannot listen on {listen}:{port}: {exc.strerror or exc}")
    connections: dict = {}
    made: dict = {}
    live_foxglove = None
    try:
        open_buses(contexts, connections)
        for arm_id, context in contexts.items():
            typer.echo(context.headline(connections[arm_id]))
        arms = decide_zeros(contexts, connections, confirmed)
        first = next(iter(contexts.values()))
        runs = first.runs_dir if first.runs_dir.is_absolute() else Path.cwd() / first.runs_dir

        from seqrun.console.arms import create_arms_app
        from seqrun.console.catalog import Catalog
        from seqrun.service.session import ArmSession

        for a, c in contexts.items():
            made[a] = ArmSession(arms[a][0].at_loop_priority(rt_priority is not None),
                                 connections[a], project=c.project,
                                 log_root=runs, zero=arms[a][1], loop_priority=rt_priority,
                                 arm_path=c.arm_path, arm_id=a,
                                 response_timeout_s=response_timeout_s(
                                     c.arm, response_timeout_ms))
        sessions = ArmSessions(made, bases={a: c.base for a, c in contexts.items()})
        for arm_id in contexts:
            _serve_control_socket(connections[arm_id], sessions[arm_id])
        if foxglove[0] is not None:
            from seqrun.foxglove.live import LiveArm

            try:
                live_foxglove = start_foxglove(None, None, foxglove[0], typer.echo,
                                               foxglove[1], arms={
                    a: LiveArm(made[a], made[a].arm, c.base_transform())
                    for a, c in contexts.items()})
            except (OSError, RuntimeError) as exc:
                fail(f"--foxglove: the Foxglove server could not start ({exc})")
        application = create_arms_app(sessions, Catalog(first.project, runs), contexts,
                                      token=token, local_only=is_loopback(listen),
                                      start_checker=True)
        url = url_of(sock, listen, token)

        def started() -> None:
            for arm_id, connection in connections.items():
                bus = "SIMULATOR" if connection.is_simulator else connection.description
                where = ", ".join(f"{k}={v}" for k, v in
                                  contexts[arm_id].bus.kwargs.items())  # (host, port, ...)
                typer.echo(f"arm {arm_id}: {bus}" + (f" ({where})" if where else ""))
            typer.echo(f"seqrun console of arms {', '.join(contexts)}: {url}")
            typer.echo(f"token (every request but STOP needs it; the URL carries it): {token}")
            typer.echo("STOP halts every arm. Ctrl-C ends the console (any motion is "
                       "stopped first).")

        _serve_until_ended(application, sock, started,
                           lambda why: sessions.halt(why).describe())  # noqa: B023
    finally:
        sock.close()
        if live_foxglove is not None:
            live_foxglove.close()
        try:
            if made:  # a controlled stop of anything still moving, then each bus
                ArmSessions(made).close()
        finally:
            for arm_id, connection in connections.items():
                if arm_id not in made:
                    connection.close()


class _Terminated(Exception):
    """SIGTERM, raised again by uvicorn after its graceful shutdown."""


def _terminated(signum, frame) -> None:  # noqa: ANN001 - a signal handler
    raise _Terminated()


def _serve_control_socket(connection, session) -> None:
    """While the console owns a shared bus, ``seqrun status`` and ``seqrun halt`` in another
    terminal ask this session over the bus claim's control socket (one controller per bus:
    the connection holds the claim when the bus is shared; nothing to serve otherwise)."""
    claim = getattr(connection, "claim", None)
    if claim is None:
        return
    import importlib

    try:
        control_socket = importlib.import_module("seqrun.service.control_socket")
    except ImportError:  # pragma: no cover - a tree without the control socket
        return
    control_socket.serve_control(claim, session.control_handler())
