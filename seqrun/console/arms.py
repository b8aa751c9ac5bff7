"""The console of several arms (``seqrun console`` in a campaign with ``[arms.*]``).

One page, one live connection, every arm: each arm keeps the whole API of the one-arm
console under ``/api/v1/arms/{id}/...`` (its own session, telemetry, motions), and what
belongs to the console as a whole is served once:

- ``POST /api/v1/halt`` (and ``{"op": "halt"}`` on the live connection): **STOP halts
  every arm** at once and confirms each (:class:`seqrun.service.arms_console.ArmSessions`);
  the answer lists every arm, confirmed or not. No token, never refused for its body.
- ``GET /api/v1/arms``: the arms, each with its arm file, bus and ``base`` (4x4, mm: its
  base frame in the facility frame, from seqrun.toml) for the one 3D view.
- ``/api/v1/control...``: one operator holds control of the whole console.
- ``/api/v1/live``: statuses and events of every arm, each naming its arm
  (``{"type": "status", "arm": "B", "status": {...}}``); a jog names its arm.

A route of the one-arm console without an arm (``/api/v1/status``) answers 404 saying
which arms there are; an unknown arm id is 404 naming the arms.
"""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import Any

from fastapi import APIRouter, FastAPI
from fastapi.responses import JSONResponse

from seqrun.console import app as one_arm
from seqrun.console import models
from seqrun.console.bodies import one_line, printable
from seqrun.console.catalog import Catalog
from seqrun.console.checker import CheckWorker, RateLimit
from seqrun.console.live import MAX_PAGES
from seqrun.errors import Refused

API = one_arm.API


class ArmsTelemetry:
    """Every arm's telemetry as one for a page: a page's feed is attached to each."""

    def __init__(self, arms: list[Any]) -> None:
        self.arms = arms

    def attach(self, feed: Any) -> list[str]:
        history: list[str] = []
        for telemetry in self.arms:
            history += telemetry.attach(feed)
        return history

    def detach(self, feed: Any) -> None:
        for telemetry in self.arms:
            telemetry.detach(feed)

    def status_gap_s(self) -> float:
        # a batch carries the newest status of every arm: one gap for all of them
        return min(t.status_gap_s() for t in self.arms)

    @property
    def history(self) -> list[str]:
        return [text for t in self.arms for text in t.history]


class ArmsMotions:
    """Which page started what, on every arm: a page that goes stops its motions on each."""

    def __init__(self, arms: list[Any]) -> None:
        self.arms = arms

    def owns_motion(self, client: str) -> bool:
        return any(m.owns_motion(client) for m in self.arms)

    def page_gone(self, client: str) -> str | None:
        done = [d for d in (m.page_gone(client) for m in self.arms) if d]
        return "; ".join(done) or None


class ArmsConsole:
    """The console of several arms: one :class:`seqrun.console.app.Console` per arm
    (``arms``), the shared control desk, and the STOP of every arm."""

    def __init__(self, sessions: Any, catalog: Catalog, contexts: dict[str, Any]) -> None:
        self.sessions = sessions
        self.catalog = catalog
        self.contexts = contexts
        self.checker = CheckWorker()
        rate = RateLimit(what="check")
        self.arms: dict[str, one_arm.Console] = {
            a: one_arm.Console(sessions[a], catalog, sessions[a].arm, arm_id=a,
                               checker=self.checker, check_rate=rate)
            for a in sessions.arm_ids}
        self.control = sessions.control
        self.telemetry = ArmsTelemetry([c.telemetry for c in self.arms.values()])
        self.motions = ArmsMotions([c.motions for c in self.arms.values()])
        self.max_pages = MAX_PAGES
        self.live_connections = 0
        self._ids = itertools.count(1)

    @property
    def arm_ids(self) -> tuple[str, ...]:
        return tuple(self.arms)

    def new_client_id(self) -> str:
        return f"page-{next(self._ids)}"

    def new_api_id(self) -> str:
        return f"api-{next(self._ids)}"

    def unknown(self, arm_id: str) -> str:
        return (f"unknown arm '{one_line(printable(arm_id))[:40]}' (this console serves arms "
                f"{', '.join(self.arm_ids)})")

    def arm_consoles(self, arm_id: str | None, *, every_if_none: bool = False
                     ) -> list[one_arm.Console]:
        """The console of the arm ``arm_id``; none named: every arm's if
        ``every_if_none`` (ending a jog), else refused (which arm?)."""
        if arm_id is None:
            if every_if_none:
                return list(self.arms.values())
            raise Refused(f"which arm? this console serves arms {', '.join(self.arm_ids)} "
                          "(name one: \"arm\")")
        if arm_id not in self.arms:
            raise Refused(self.unknown(arm_id))
        return [self.arms[arm_id]]

    def status_dict(self) -> dict[str, Any]:
        """Every arm's status (the live hello)."""
        return {"arms": {a: c.status_dict() for a, c in self.arms.items()}}

    def arms_list(self) -> list[dict[str, Any]]:
        out = []
        for arm_id, console in self.arms.items():
            context = self.contexts.get(arm_id)
            connection = self.sessions[arm_id].connection
            out.append({
                "id": arm_id, "name": console.arm.name,
                "arm_file": str(context.arm_path) if context is not None else None,
                "bus": connection.description, "simulator": connection.is_simulator,
                "base": (context.base_transform().tolist() if context is not None
                         else [[1.0 if i == j else 0.0 for j in range(4)] for i in range(4)]),
            })
        return out

    def halt(self, reason: str) -> dict[str, Any]:
        return self.sessions.halt(reason).as_dict()

    def halter(self, request: Any) -> Any:
        """Whom a command that failed on the bus halts: its arm (every arm for a route of
        the whole console)."""
        parts = request.url.path.split("/")  # "", "api", "v1", "arms", ID, ...
        if len(parts) > 4 and parts[3] == "arms" and parts[4] in self.arms:
            return self.arms[parts[4]]
        return self

    def halt_after_bus_fault(self, where: str, exc: BaseException) -> str:
        result = self.sessions.halt(f"bus fault in a console command ({printable(where)[:80]})")
        return ("every arm was halted" if result.confirmed
                else f"the Halt FAILED for arm {', '.join(result.not_confirmed)}: use the "
                     "emergency stop")

    async def halt_now(self, reason: str) -> dict[str, Any]:
        """:meth:`halt` on a thread of its own, started at once (as one arm's STOP)."""
        return await one_arm.halt_on_thread(self.halt, reason, "console-halt-arms")


class _ArmsRunActivity:
    """A campaign run as a page's motion (:class:`seqrun.console.motions.Motions`: done,
    and abort through the arm's session)."""

    def __init__(self, run: Any) -> None:
        self.run = run

    @property
    def done(self) -> bool:
        return bool(self.run.done)


def arm_path(arm_id: str) -> str:
    return f"{API}/arms/{arm_id}"


def create_arms_app(sessions: Any, catalog: Catalog, contexts: dict[str, Any], *,
                    token: str | None = None, local_only: bool = True,
                    max_pages: int = MAX_PAGES, start_checker: bool = False) -> FastAPI:
    """The ASGI application of the console of several arms (``sessions``:
    :class:`~seqrun.service.arms_console.ArmSessions`; ``contexts``: arm id -> its
    :class:`~seqrun.service.arm_context.ArmContext`, for the arm files, buses and bases).
    The options as :func:`seqrun.console.app.create_app`."""
    console = ArmsConsole(sessions, catalog, contexts)
    console.max_pages = max_pages
    app = one_arm.new_app(console, list(console.arms.values()), start_checker=start_checker,
                          title="seqrun console (several arms)", halter=console.halter,
                          description="The operator console of several arms: each arm's "
                                      "API under /api/v1/arms/{id}; STOP (/api/v1/halt) "
                                      "halts every arm.")
    top = APIRouter(prefix=API)
    one_arm.halt_route(top, console, "STOP: every arm halted at once, each confirmed; never "
                                     "refused for its body", halted="every arm")

    @top.get("/arms", summary="The arms: id, arm file, bus, base pose in the facility frame")
    def arms() -> list[dict[str, Any]]:
        return console.arms_list()

    @top.get("/sequences", summary="The project's sequences; ``arms``: whether it names the "
                                    "arms it moves (POST /run runs it), else it is a sequence "
                                    "of one arm (POST /arms/{id}/run runs it on that arm)")
    def sequences() -> list[dict[str, Any]]:
        from seqrun.service.arms_check import addresses_arms

        return [s | {"arms": addresses_arms(Path(s["file"]))}
                for s in console.catalog.sequences()]

    @top.get("/runs", summary="Every past run of the campaign, newest first (a run of several "
                              "arms: its parts, each arm's run folder by arm id)")
    def runs() -> list[dict[str, Any]]:
        return console.catalog.runs()

    @top.post("/run", summary="Run a sequence of several arms (validated as seqrun run: each "
                              "arm, the arms against each other; a run folder part per arm)",
              openapi_extra=one_arm.documented(models.ArmsRunBody))
    def run(body: models.ArmsRunBody = one_arm.json_body(models.ArmsRunBody),
            token: one_arm.ControlHeader = None) -> dict[str, Any]:
        by = console.control.require(token, f"run {body.sequence}")
        path = console.catalog.sequence_path(body.sequence)
        started = sessions.run_sequence(path, speed=body.speed, by=by.name)
        for arm_id in started.arms:  # a page that goes stops its run, as for one arm
            console.arms[arm_id].motions.started(by.id, "run", _ArmsRunActivity(started))
        return {"accepted": True, **started.as_dict()}

    @top.get("/run", summary="The sequence of several arms under way or last (null: none)")
    def run_state() -> Any:
        return None if sessions.run is None else sessions.run.as_dict()

    @top.post("/run/abort", summary="A controlled stop of every arm (any client)")
    def run_abort() -> dict[str, Any]:
        sessions.abort("operator abort (console)")
        return {"aborted": True}

    one_arm.control_routes(top, console)
    app.include_router(top)
    for arm_id, arm in console.arms.items():
        app.include_router(one_arm.build_router(arm, prefix=arm_path(arm_id),
                                                console_wide=False))

    @app.api_route(f"{API}/arms/{{arm_id}}/{{rest:path}}",
                   methods=["GET", "POST", "PUT", "DELETE", "PATCH"],
                   include_in_schema=False)
    async def unknown_arm(arm_id: str, rest: str) -> JSONResponse:
        if arm_id not in console.arms:
            return JSONResponse({"error": console.unknown(arm_id)}, status_code=404)
        return JSONResponse({"error": "Not Found"}, status_code=404)

    @app.api_route(f"{API}/{{rest:path}}", methods=["GET", "POST", "PUT", "DELETE", "PATCH"],
                   include_in_schema=False)
    async def which_arm(rest: str) -> JSONResponse:
        return JSONResponse({"error": one_line(
            f"/api/v1/{printable(rest)[:60]}: this console serves arms "
            f"{', '.join(console.arm_ids)}: address one, /api/v1/arms/ID/"
            f"{printable(rest)[:60]}")}, status_code=404)

    stops = frozenset({f"{API}/halt", *(f"{arm_path(a)}/halt" for a in console.arm_ids)})
    one_arm.serve_page(app, console, "arms.html", stops, token=token, local_only=local_only)
    return app


__all__ = ["ArmsConsole", "create_arms_app"]
