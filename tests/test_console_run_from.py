"""Run from here in the console (issue 40, item 5): ``POST /run {first_step: N}`` runs as
``seqrun run --from N`` (the steps before N are only tracked), checked before anything
moves from the arm's measured pose: refused with the reason when the arm does not stand
where step N expects it, refused in one line for a bad N, refused without control. On a
real arm session over the simulated arm (real time: a console session polls its arm in
threads); the moves are a few degrees so that a run takes about a second."""

from __future__ import annotations

import gzip
import json
import re
import time
from pathlib import Path

import pytest
from consolekit import LOCAL, console_setup, refused, take_control, wait_for
from fastapi.testclient import TestClient

from seqrun.errors import Refused

#: Step 2 expects j1 at 6° (where step 1 leaves it); every other joint at Park.
FROM_HERE = """\
name: From here
steps:
  - move: {joints: {j1: 6}, label: Out}
  - move: {joints: {j1: 2}, label: Half back}
  - move: {joints: {j1: 0}, label: Back}
"""


@pytest.fixture
def setup(tmp_path):
    s = console_setup(tmp_path)
    (s.folder / "sequences" / "from_here.yaml").write_text(FROM_HERE)
    yield s
    s.close()


@pytest.fixture
def client(setup):
    with TestClient(setup.app(), base_url=LOCAL, raise_server_exceptions=False) as c:
        take_control(c)
        yield c


def armed(client) -> None:
    for path in ("/api/v1/arm-up", "/api/v1/home"):
        r = client.post(path)
        assert r.status_code == 200, r.text


def status(client) -> dict:
    return client.get("/api/v1/status").json()


def idle(client, timeout: float = 30.0) -> dict:
    return wait_for(lambda: (s := status(client))["activity"]
                    not in ("moving", "jogging", "running", "paused") and s, timeout)


def j1(client) -> float:
    return next(j["position_deg"] for j in status(client)["joints"] if j["name"] == "j1")


def run_folders(setup) -> list[Path]:
    return sorted(p for p in setup.runs.glob("*") if p.is_dir()) if setup.runs.exists() else []


def test_bad_first_steps_are_refused_in_one_line_and_nothing_is_sent(client, setup):
    armed(client)
    before = time.perf_counter()
    for body in ({"first_step": 0}, {"first_step": -1}, {"first_step": True},
                 {"first_step": "2"}, {"first_step": 2.0}, {"first_step": None}):
        refused(client.post("/api/v1/run", json={"sequence": "from_here.yaml", **body}), 422,
                "first_step")
    refused(client.post("/api/v1/run", json={"sequence": "from_here.yaml", "first_step": 4}),
            409, "first step 4", "1-3")
    assert setup.wire.motions(before) == 0
    assert run_folders(setup) == []


def test_the_service_refuses_a_boolean_first_step(setup):
    """The gate is the service's: ``True`` is not step 1, whichever face sends it."""
    for bad in (True, 0, 4, "2"):
        with pytest.raises(Refused, match="first step"):
            setup.session.run_sequence(setup.folder / "sequences" / "from_here.yaml",
                                       first_step=bad)


def test_without_control_run_from_here_is_refused(setup):
    with TestClient(setup.app(), base_url=LOCAL, raise_server_exceptions=False) as c:
        before = time.perf_counter()
        refused(c.post("/api/v1/run", json={"sequence": "from_here.yaml", "first_step": 2}),
                409, "control")
        assert setup.wire.motions(before) == 0


def test_refused_with_the_reason_when_the_arm_is_not_where_the_step_expects_it(client, setup):
    armed(client)
    wait_for(lambda: status(client)["updated_at"] is not None)
    before = time.perf_counter()
    message = refused(client.post("/api/v1/run", json={"sequence": "from_here.yaml",
                                                       "first_step": 2}), 409,
                      "from_here.yaml:4:", "not where this step expects it", "j1",
                      "expected 6.00°")
    assert "after steps 1-1" in message, message
    assert setup.wire.motions(before) == 0
    assert run_folders(setup) == []
    assert status(client)["activity"] not in ("running", "moving")


@pytest.mark.slow  # real-time motion: a move to 6°, then two steps
def test_run_from_a_step_runs_only_the_steps_from_there(client, setup):
    armed(client)
    r = client.post("/api/v1/move/joints", json={"joints": {"j1": 6}})
    assert r.status_code == 200, r.text
    idle(client)
    assert j1(client) == pytest.approx(6, abs=0.3)
    r = client.post("/api/v1/run", json={"sequence": "from_here.yaml", "first_step": 2})
    assert r.status_code == 200, r.text
    running = wait_for(lambda: (s := status(client))["run"] and s["run"]["step"] and s, 30)
    assert running["run"]["first_step"] == 2 and running["run"]["step"] >= 2, running["run"]
    idle(client)
    assert j1(client) == pytest.approx(0, abs=0.3)
    (folder,) = run_folders(setup)
    report = json.loads(wait_for(lambda: (folder / "report.json").exists()
                                 and (folder / "report.json").read_text()))
    assert report["status"] == "passed", report
    assert report["first_step"] == 2
    assert [s["status"] for s in report["steps"]] == ["skipped", "passed", "passed"]
    html = wait_for(lambda: (folder / "report.html").exists()
                    and (folder / "report.html").read_text())
    assert re.search(r"first step</th>\s*<td>2<", html), "report.html does not say step 2"
    events = [json.loads(line) for line in
              gzip.decompress((folder / "events.jsonl.gz").read_bytes()).splitlines()]
    started = [e for e in events if e["type"] == "run_started"]
    assert started and started[0]["first_step"] == 2
    assert sorted({e["step"] for e in events if e["type"] == "step_started"}) == [2, 3]
