"""The console's web application: the page, the ``/api/v1`` HTTP API and the live WebSocket
(:mod:`seqrun.console.live`).

Everything goes through the arm session (:mod:`seqrun.service.session`); the console holds
no bus and no executor. Commands need control (:mod:`seqrun.service.control`); STOP needs
nothing and is never refused for its body. Bodies are strict (:mod:`seqrun.console.bodies`).
Refusals are one line, ``{"error": "..."}``: 409 when the session refuses (wrong state,
unknown joint or pose, out of limits, not in control), 422 for a malformed request (NaN,
unknown or repeated keys, wrong types), 413/408 a body too large or slow, 429 too many
checks, 400 for bad input, 401/403 from the access guard, 404/405 as any HTTP error. A
command that fails on the bus halts the arm (503); any other exception in a handler is a
500 for that request only (logged, escaped).
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import logging
import re
import threading
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Annotated, Any

from fastapi import APIRouter, Depends, FastAPI, Header, Request, WebSocket
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, HTMLResponse, JSONResponse, Response
from fastapi.staticfiles import StaticFiles
from starlette.exceptions import HTTPException as StarletteHTTPException

from seqrun.console import models
from seqrun.console.bodies import (BODY_CUT, Malformed, check_body, one_line, printable,
                                   read_model, to_model)
from seqrun.console.catalog import Catalog
from seqrun.console.checker import CheckWorker, RateLimit, TooMany
from seqrun.console.guard import COOKIE, AccessGuard
from seqrun.console.limits import RequestLimits
from seqrun.console.live import MAX_PAGES, PAGE_SILENCE_S, live  # noqa: F401 (tests' name)
from seqrun.console.motions import Motions
from seqrun.service.kinematics import arm_scene
from seqrun.console.telemetry import Telemetry, jsonable
from seqrun.errors import Refused, SeqrunError, UserInputError
from seqrun.service.control import Client

log = logging.getLogger(__name__)

API = "/api/v1"
STATIC = Path(__file__).resolve().parent / "static"
#: The control secret a client got when it took control (seqrun/service/control.py): every
#: command presents it; the public client id is no credential.
ControlHeader = Annotated[str | None, Header(alias="X-Seqrun-Control")]
#: A part of the pages shared by both (``<!-- include parts/motion.html -->``).
_INCLUDE = re.compile(r"<!-- include (parts/[a-z0-9_-]+\.html) -->")


def json_body(model: type[Any]) -> Any:
    """A handler's strictly parsed body (:mod:`seqrun.console.bodies`): the dependency and
    its OpenAPI description."""
    async def parse(request: Request) -> Any:
        return await read_model(request, model)

    return Depends(parse)


def documented(model: type[Any]) -> dict[str, Any]:
    """The request body's schema for the OpenAPI document (the body is read by
    :func:`json_body`, not by the framework)."""
    return {"requestBody": {"required": True, "content": {"application/json": {
        "schema": model.model_json_schema()}}}}


def _validation_line(exc: RequestValidationError) -> str:
    errors = exc.errors()
    if not errors:
        return "malformed request"
    first = errors[0]
    if tuple(first.get("loc", ())) == ("body",):
        return one_line(f"the request body must be a JSON object (Content-Type: "
                        f"application/json): {first.get('msg', 'invalid')}")
    where = ".".join(str(p) for p in first.get("loc", ()) if p != "body")
    more = f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""
    return one_line(f"{where + ': ' if where else ''}{first.get('msg', 'invalid')}{more}")


class Console:
    """What the handlers share: the session, the project catalog, the page feeds."""

    def __init__(self, session: Any, catalog: Catalog, arm: Any, *,
                 arm_id: str | None = None, checker: CheckWorker | None = None,
                 check_rate: RateLimit | None = None) -> None:
        self.session = session
        self.catalog = catalog
        self.arm = arm
        #: The arm's id in a console of several arms (:mod:`seqrun.console.arms`); None:
        #: the console of one arm.
        self.arm_id = arm_id
        #: GET /arm: the arm's chain, limits and volumes, and which arm of the campaign's
        #: several it is (``[arms.ID]``; None: a campaign of one arm).
        self.scene = arm_scene(arm) | {"arm_id": getattr(session, "arm_id", None)}
        self.motions = Motions(session)
        #: Who holds control: the session's (shared with its other faces).
        self.control = session.control
        self.checker = checker if checker is not None else CheckWorker()
        self.max_pages = MAX_PAGES
        self.live_connections = 0
        self.check_rate = check_rate if check_rate is not None else RateLimit(what="check")
        self.telemetry = Telemetry(session, status_dict=self.status_dict, arm_id=arm_id)
        self._ids = itertools.count(1)

    def new_client_id(self) -> str:
        return f"page-{next(self._ids)}"

    def new_api_id(self) -> str:
        return f"api-{next(self._ids)}"

    def arm_consoles(self, arm_id: str | None, *, every_if_none: bool = False
                     ) -> list[Console]:
        """The console of the arm a live message names: this one (one arm: a message
        names none)."""
        if arm_id is not None:
            raise Refused(f"arm '{one_line(printable(arm_id))[:40]}': this console serves "
                          "one arm; leave 'arm' out")
        return [self]

    def status_dict(self) -> dict[str, Any]:
        return jsonable(self.session.status())

    def halt(self, reason: str) -> dict[str, Any]:
        result = self.session.halt(reason)
        return {**jsonable(result), "message": result.describe()}

    async def halt_now(self, reason: str) -> dict[str, Any]:
        return await halt_on_thread(self.halt, reason, "console-halt")

    def halt_after_bus_fault(self, where: str, exc: BaseException) -> str:
        """A command could not do or confirm what it says on the bus: Halt, as ``seqrun
        run`` does on a bus fault."""
        log.error("console: %s failed on the bus: %s", printable(where), printable(repr(exc)))
        try:
            self.session.halt(f"bus fault in a console command ({printable(where)[:80]})")
            return "the arm was halted"
        except Exception as halt_exc:  # noqa: BLE001 - report, never mask the first error
            log.error("console: the Halt after a bus fault failed: %s",
                      printable(repr(halt_exc)))
            return "the Halt FAILED: use the emergency stop"


async def halt_on_thread(halt: Callable[[str], dict[str, Any]], reason: str,
                         name: str) -> dict[str, Any]:
    """``halt(reason)`` on a thread of its own, started at once: a STOP never waits for the
    web server's worker threads (all of them may be busy with blocking commands)."""
    loop = asyncio.get_running_loop()
    done: asyncio.Future[dict[str, Any]] = loop.create_future()

    def run() -> None:
        result: Any = None
        failure: BaseException | None = None
        try:
            result = halt(reason)
        except BaseException as exc:  # noqa: BLE001 - handed to the awaiting request
            failure = exc
        try:
            loop.call_soon_threadsafe(_settle, done, result, failure)
        except RuntimeError:  # the server stopped meanwhile: no request awaits the answer
            log.warning("console: %s ended after the server stopped: %s", name,
                        printable(repr(failure)) if failure else "done")

    threading.Thread(target=run, name=name, daemon=True).start()
    return await done


def _settle(future: asyncio.Future[Any], result: Any, exc: BaseException | None) -> None:
    if future.done():
        return
    if exc is not None:
        future.set_exception(exc)
    else:
        future.set_result(result)


class CrashGuard:
    """ASGI middleware: an exception no handler expected is a 500 for that request, logged
    (escaped), and nothing else: the arm's activities run in the session, which halts on
    their faults itself; a bug in serving one request is no fault of the arm, and a Halt
    there would stop a run in the operator's name (a GET from any web page could do it)."""

    def __init__(self, app: Any, console: Any) -> None:
        self.app = app
        self.console = console

    async def __call__(self, scope: Any, receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        started = False

        async def tracking_send(message: Any) -> None:
            nonlocal started
            if message["type"] == "http.response.start":
                started = True
            await send(message)

        try:
            await self.app(scope, receive, tracking_send)
        except Exception as exc:  # noqa: BLE001 - the point: nothing crashes silently
            log.error("console: internal error in %s %s: %s", scope.get("method", "?"),
                      printable(scope.get("path", "?")), printable(repr(exc)),
                      exc_info=log.isEnabledFor(logging.DEBUG))
            if not started:
                body = json.dumps({"error": one_line(printable(
                    f"internal error ({type(exc).__name__}: {exc})"))}).encode()
                await send({"type": "http.response.start", "status": 500,
                            "headers": [(b"content-type", b"application/json")]})
                await send({"type": "http.response.body", "body": body})


def check_start(now: Any) -> tuple[dict[str, float] | None, bool]:
    """Where a check's dry run starts: the measured joints (nothing measured yet: Park, as
    ``seqrun validate``), and whether the arm is up (every module homed, none halted or in
    error: a sequence without the start-up steps is checked as it would run)."""
    measured = dict(now.joints_deg)
    start = None if any(v is None for v in measured.values()) else measured
    up = all("HOME_OK" in j.flags and not {"HALTED", "ERROR"} & set(j.flags)
             for j in now.joints) and now.activity not in ("halted", "faulted")
    return start, up


def _activity(activity: Any) -> dict[str, Any]:
    return {"accepted": True, "kind": getattr(activity, "kind", None)}


def _confirmed(result: Any) -> Any:
    """A blocking command's result; one that did not succeed (not valid from the measured
    state, not confirmed) is a 409 with its one line, not an "ok"."""
    body = jsonable(result)
    if getattr(result, "ok", True) is False:
        message = one_line(f"{getattr(result, 'kind', 'command')} "
                           f"{getattr(result, 'status', 'failed')}: "
                           f"{getattr(result, 'message', '')}")
        return JSONResponse({"error": message, "result": body}, status_code=409)
    return body


def build_router(console: Console, *, prefix: str = API,
                 console_wide: bool = True) -> APIRouter:
    """The routes of one arm's console under ``prefix``; ``console_wide``: with the
    routes of who holds control (a console of several arms serves those once, for all its
    arms: :mod:`seqrun.console.arms`)."""
    api = APIRouter(prefix=prefix)
    session = console.session
    catalog = console.catalog
    motions = console.motions

    # -- reading ----------------------------------------------------------------------
    @api.get("/status", summary="The arm now: joints, velocities, targets, states, pose")
    def status() -> dict[str, Any]:
        return console.status_dict()

    @api.get("/arm", summary="The arm description's chain, limits, guards and link volumes")
    def arm() -> dict[str, Any]:
        return console.scene

    @api.get("/poses", summary="Every named pose (campaign poses first, then the shipped)")
    def poses() -> list[dict[str, Any]]:
        return catalog.poses(console.arm)

    @api.get("/sequences", summary="The project's sequences")
    def sequences() -> list[dict[str, str]]:
        return catalog.sequences()

    @api.post("/sequences/{name:path}/check",
              summary="Validation findings and the dry-run report from the arm's position "
                      "now (a worker process; 3 at once, then one per 3 s)")
    async def check(name: str) -> Any:
        console.check_rate.take()  # TooMany: 429
        try:
            start, up = check_start(session.status())
            answer = await asyncio.to_thread(console.checker.check, catalog, name, start,
                                             started=up)
            return Response(answer, media_type="application/json")  # (encoded there)
        finally:
            console.check_rate.give_back()

    @api.get("/runs", summary="Past runs, newest first (in a campaign with several arms: "
                               "this arm's, and those of several arms it was part of)")
    def runs() -> list[dict[str, Any]]:
        return catalog.runs(session.arm_id)

    @api.get("/runs/{run_id:path}/{name}", summary="A file of a run folder (report.html, "
                                                 "...; a run of several arms: ID/ARM/...)")
    def run_file(run_id: str, name: str) -> FileResponse:
        return FileResponse(catalog.run_file(run_id, name))

    @api.get("/events", summary="Recent events (the event log), oldest first")
    def events() -> Response:
        # The history holds each event's message as sent to the pages: its event part is
        # passed on as it is (a GET costs little: nothing decoded, nothing encoded again).
        prefix, parts = '{"type":"event","event":', []
        for text in list(console.telemetry.history):
            if text.startswith(prefix) and text.endswith("}"):
                parts.append(text[len(prefix):-1])
            else:
                parts.append(json.dumps(json.loads(text)["event"]))
        return Response("[" + ",".join(parts) + "]", media_type="application/json")

    # -- commands -----------------------------------------------------------------------
    halt_route(api, console, "STOP: the Halt broadcast at once, then confirmed; never "
                             "refused for its body", halted="the arm")

    def commander(token: str | None, what: str) -> Client:
        """The client that commands ``what``: ``token`` must be the holder's secret (else
        409 naming the holder). STOP and the stops (abort, pause, end a jog) need none."""
        return console.control.require(token, what)

    @api.post("/reset", summary="Reset every module (clears a Halt), confirmed")
    def reset(token: ControlHeader = None) -> Any:
        commander(token, "reset")
        return _confirmed(session.reset())

    @api.post("/home", summary="Home every module (enables the motors), confirmed")
    def home(token: ControlHeader = None) -> Any:
        commander(token, "home")
        return _confirmed(session.home())

    @api.post("/arm-up", summary="Arm: reset, then write the arm file's limits")
    def arm_up(token: ControlHeader = None) -> Any:
        commander(token, "arm")
        return _confirmed(session.arm_up())

    @api.post("/move/pose", summary="Move to a named pose (validated, planned, streamed)",
              openapi_extra=documented(models.PoseMove))
    def move_pose(body: models.PoseMove = json_body(models.PoseMove),
                  token: ControlHeader = None) -> dict[str, Any]:
        by = commander(token, f"move to {body.name}")
        activity = session.move_to_pose(body.name, velocity_scale=body.velocity_scale,
                                        by=by.name)
        motions.started(by.id, "move", activity)
        return _activity(activity)

    @api.post("/move/joints", summary="Move to joint targets in user degrees (MOVE)",
              openapi_extra=documented(models.JointMap))
    def move_joints(body: models.JointMap = json_body(models.JointMap),
                    token: ControlHeader = None) -> dict[str, Any]:
        by = commander(token, "move")
        activity = session.move_to_joints(dict(body.joints), by=by.name)
        motions.started(by.id, "move", activity)
        return _activity(activity)

    @api.post("/velocities", summary="Per-joint velocity of the console's moves, deg/s (ALLVEL)",
              openapi_extra=documented(models.JointMap))
    def velocities(body: models.JointMap = json_body(models.JointMap),
                   token: ControlHeader = None) -> Any:
        commander(token, "move velocities")
        return jsonable(session.set_move_velocities(dict(body.joints)))

    @api.post("/jog", summary="Jog one joint; renew within 200 ms or it stops (deadman)",
              openapi_extra=documented(models.JogBody))
    def jog(body: models.JogBody = json_body(models.JogBody),
            token: ControlHeader = None) -> dict[str, Any]:
        by = commander(token, "jog")
        session.jog(body.joint, body.speed_scale, by=by.name, mode=body.mode)
        motions.started(by.id, "jog")
        return {"accepted": True}

    @api.post("/jog/stop", summary="End the jog (controlled stop; any client)")
    def jog_stop(token: ControlHeader = None) -> Any:
        result = session.jog_stop()  # a controlled stop
        holder = console.control.holder_of(token)
        motions.jog_ended(holder.id if holder is not None else None)
        return jsonable(result)

    @api.get("/gripper", summary="The gripper: width, holding, state (null: none)")
    def gripper() -> Any:
        return jsonable(session.gripper_state())

    @api.post("/gripper/grip", summary="Grip a part of a width with a force (N)",
              openapi_extra=documented(models.GripBody))
    def grip(body: models.GripBody = json_body(models.GripBody),
             token: ControlHeader = None) -> dict[str, Any]:
        by = commander(token, "grip")
        activity = session.grip(body.part_width_mm, body.force_n, by=by.name)
        motions.started(by.id, "move", activity)
        return _activity(activity)

    @api.post("/gripper/release", summary="Open the gripper to a width (mm)",
              openapi_extra=documented(models.ReleaseBody))
    def release(body: models.ReleaseBody = json_body(models.ReleaseBody),
                token: ControlHeader = None) -> dict[str, Any]:
        by = commander(token, "release")
        activity = session.release(body.width_mm, by=by.name)
        motions.started(by.id, "move", activity)
        return _activity(activity)

    @api.post("/run", summary="Run a sequence (validated first; a run folder as seqrun run)",
              openapi_extra=documented(models.RunBody))
    def run(body: models.RunBody = json_body(models.RunBody),
            token: ControlHeader = None) -> dict[str, Any]:
        by = commander(token, f"run {body.sequence}")
        path = catalog.sequence_path(body.sequence)
        activity = session.run_sequence(path, speed=body.speed, step_mode=body.step_mode,
                                        first_step=body.first_step, by=by.name)
        motions.started(by.id, "run", activity)
        return _activity(activity)

    @api.post("/shutdown", summary="Run the shutdown sequence (to Totem, then power-off)")
    def shutdown(token: ControlHeader = None) -> dict[str, Any]:
        by = commander(token, "shut down")
        activity = session.run_sequence(catalog.shutdown_sequence(), by=by.name)
        motions.started(by.id, "run", activity)
        return _activity(activity)

    for verb, needs_control in (("pause", False), ("resume", True), ("step", True),
                                ("abort", False)):
        def run_control(token: ControlHeader = None, verb: str = verb,
                        needs_control: bool = needs_control) -> Any:
            if needs_control:
                commander(token, verb)
            return jsonable(getattr(session, verb)())
        api.add_api_route(f"/run/{verb}", run_control, methods=["POST"],
                          summary=f"{verb.capitalize()} the run under way"
                                  + ("" if needs_control else " (any client)"))

    @api.post("/answer", summary="Answer a confirm step (confirm_requested event)",
              openapi_extra=documented(models.AnswerBody))
    def answer(body: models.AnswerBody = json_body(models.AnswerBody),
               token: ControlHeader = None) -> Any:
        commander(token, "answer")
        return jsonable(session.answer(body.question_id, body.yes, body.name, body.choice))

    @api.post("/poses", summary="Save the arm's measured joints as a pose file",
              openapi_extra=documented(models.SavePoseBody))
    def save_pose(body: models.SavePoseBody = json_body(models.SavePoseBody),
                  token: ControlHeader = None) -> dict[str, Any]:
        commander(token, "save pose")
        path = session.save_pose(body.name, overwrite=body.overwrite)
        return {"saved": str(path)}

    if console_wide:
        control_routes(api, console)
    return api


def halt_route(api: APIRouter, console: Any, summary: str, *, halted: str) -> None:
    """``POST /halt``, STOP: ``console.halt_now`` is started before anything about the
    request is read, so a STOP with a malformed, oversized or slow body still stops
    (``halted``: "the arm", "every arm"), then says what was wrong with it."""
    @api.post("/halt", summary=summary, openapi_extra=documented(models.HaltBody))
    async def halt(request: Request) -> Any:
        halting = asyncio.ensure_future(console.halt_now("STOP (console)"))
        note = reason = None
        try:
            raw = await request.body()
            data = check_body(raw, request.headers.get("content-type"),
                              request.scope.get(BODY_CUT))
            reason = to_model({} if data is None else data, models.HaltBody).reason
        except Malformed as exc:
            note = f"{halted} was halted; the request body was refused: {exc}"
        except Exception as exc:  # noqa: BLE001 - a lost connection: the Halt goes on
            note = f"{halted} was halted; the request body could not be read: {exc!r}"
        answer = await halting
        if reason is not None:
            answer["reason"] = reason
        if note is not None:
            answer["note"] = one_line(note)
        return answer


def control_routes(api: APIRouter, console: Any) -> None:
    """Who holds control: ``/control``, take, release, leave (``console``: its ``control``
    desk and ``new_api_id()``). A page takes and gives control up on its live connection
    (its secret comes back there, for that page alone); these routes are for API clients."""
    @api.get("/control", summary="Who holds control and who is connected (public ids and "
                                 "names; never a secret)")
    def control_state() -> dict[str, Any]:
        return console.control.state().as_dict()

    @api.post("/control/take", summary="An API client joins and takes control: the answer's "
                                        "token is its secret, sent as X-Seqrun-Control with "
                                        "every command (take_over: from the holder, whose "
                                        "motion is stopped first)",
              openapi_extra=documented(models.TakeControlBody))
    def take_control(body: models.TakeControlBody = json_body(models.TakeControlBody)
                     ) -> dict[str, Any]:
        client = console.new_api_id()
        grant = console.control.join_and_take(
            client, f"{one_line(printable(body.name))} ({client})", "api",
            take_over=body.take_over)
        return grant.as_dict()

    @api.post("/control/release", summary="The holder gives control up (its motion ends "
                                           "with a controlled stop; an API client leaves)")
    def release_control(token: ControlHeader = None) -> dict[str, Any]:
        return console.control.release(token).as_dict()

    @api.post("/control/leave", summary="An API client leaves (as release)")
    def leave(token: ControlHeader = None) -> dict[str, Any]:
        return console.control.release(token).as_dict()


def index_page(request: Request, page: str = "index.html") -> HTMLResponse:
    html = _INCLUDE.sub(lambda m: (STATIC / m[1]).read_text(encoding="utf-8"),
                        (STATIC / page).read_text(encoding="utf-8"))
    response = HTMLResponse(html, headers={"Cache-Control": "no-store"})
    token = request.query_params.get("token")
    if token:  # the URL printed at start: the page's own requests carry it as a cookie
        response.set_cookie(COOKIE, token, httponly=True, samesite="strict")
    return response


def install_error_handlers(app: FastAPI, halter: Any) -> None:
    """The one-line refusals of every route (see the module doc); ``halter(request)``: the
    console whose arm a command that failed on the bus halts."""
    @app.exception_handler(Refused)
    async def refused(_: Request, exc: Refused) -> JSONResponse:
        return JSONResponse({"error": one_line(str(exc))}, status_code=409)

    @app.exception_handler(UserInputError)
    async def bad_input(_: Request, exc: UserInputError) -> JSONResponse:
        return JSONResponse({"error": one_line(str(exc))}, status_code=400)

    @app.exception_handler(TooMany)
    async def too_many(_: Request, exc: TooMany) -> JSONResponse:
        return JSONResponse({"error": one_line(str(exc))}, status_code=429,
                            headers={"Retry-After": str(max(1, round(exc.retry_after_s)))})

    @app.exception_handler(StarletteHTTPException)
    async def http_error(_: Request, exc: StarletteHTTPException) -> JSONResponse:
        # 404, 405, ...: the documented {"error"} body, as every refusal
        return JSONResponse({"error": one_line(printable(str(exc.detail)))},
                            status_code=exc.status_code, headers=exc.headers)

    @app.exception_handler(Malformed)
    async def malformed_body(_: Request, exc: Malformed) -> JSONResponse:
        return JSONResponse({"error": one_line(str(exc))}, status_code=exc.status)

    @app.exception_handler(RequestValidationError)
    async def malformed(_: Request, exc: RequestValidationError) -> JSONResponse:
        return JSONResponse({"error": _validation_line(exc)}, status_code=422)

    @app.exception_handler(SeqrunError)
    async def failed(request: Request, exc: SeqrunError) -> JSONResponse:
        # A command that could not do or confirm what it says (a bus or module fault).
        outcome = await asyncio.to_thread(halter(request).halt_after_bus_fault,
                                          request.url.path, exc)
        return JSONResponse({"error": one_line(f"{exc}; {outcome}")}, status_code=503)


def create_app(session: Any, catalog: Catalog, arm: Any, *, token: str | None = None,
               local_only: bool = True, max_pages: int = MAX_PAGES,
               start_checker: bool = False) -> FastAPI:
    """The ASGI application for one arm session. ``token``: required on every request but
    STOP (``seqrun console`` always makes one; None: no token, for embedding and tests);
    ``local_only``: the Host header must name this machine; ``max_pages``: live
    connections at most; ``start_checker``: start the check's worker process with the app
    (else at the first check)."""
    console = Console(session, catalog, arm)
    console.max_pages = max_pages
    app = new_app(console, [console], start_checker=start_checker, title="seqrun console",
                  description="The operator console's API: what the page uses, for a "
                              "facility coordinator or a second tool too.",
                  halter=lambda _: console)
    app.include_router(build_router(console))
    serve_page(app, console, "index.html", frozenset({f"{API}/halt"}), token=token,
               local_only=local_only)
    return app


def new_app(console: Any, arms: list[Console], *, start_checker: bool, title: str,
            description: str, halter: Callable[[Any], Any]) -> FastAPI:
    """A console's application before its routes: the telemetry of each of its ``arms``
    running while it serves, the check's worker (started with it: ``start_checker``), the
    one-line refusals (``halter(request)``: whom a command that failed on the bus halts)."""
    @contextlib.asynccontextmanager
    async def lifespan(_: FastAPI) -> AsyncIterator[None]:
        for arm in arms:
            arm.telemetry.start()
        if start_checker:
            await asyncio.to_thread(console.checker.start)
        try:
            yield
        finally:
            for arm in arms:
                arm.telemetry.stop()
            console.checker.close()

    app = FastAPI(title=title, version="1", lifespan=lifespan, description=description,
                  # No Swagger UI: it loads its scripts from a CDN (the facility has no
                  # internet); the OpenAPI document itself is served.
                  openapi_url=f"{API}/openapi.json", docs_url=None, redoc_url=None)
    app.state.console = console
    install_error_handlers(app, halter)
    return app


def serve_page(app: FastAPI, console: Any, page: str, stops: frozenset[str], *,
               token: str | None, local_only: bool) -> None:
    """The live WebSocket, the page (``page`` of static/) and its files, and the guards:
    every request but the STOPs (``stops``: paths of ``POST``) needs the token, and is
    cut to the request limits (a STOP's body is read whatever it is)."""
    @app.websocket(f"{API}/live")
    async def live_socket(ws: WebSocket) -> None:
        await live(console, ws)

    def index(request: Request) -> HTMLResponse:
        return index_page(request, page)

    app.add_api_route("/", index, methods=["GET"], include_in_schema=False)
    app.mount("/static", StaticFiles(directory=str(STATIC)), name="static")
    app.add_middleware(CrashGuard, console=console)
    app.add_middleware(RequestLimits, always_read=stops)
    app.add_middleware(AccessGuard, token=token, local_only=local_only,
                       open_to_all=frozenset(("POST", path) for path in stops))
