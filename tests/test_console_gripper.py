"""The gripper from the console: its state, Grip and Release through the session (one-step
sequences, validated first, behind the control desk); a force above the gripper's limit
or no control is refused in one line with nothing sent to it."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from consolekit import console_setup, take_control, wait_for
from test_console_api import LOCAL, armed, idle, refused

GRIPPER_SET = 0x0E8  # requests to the gripper's module (8)


@pytest.fixture
def setup(tmp_path):
    s = console_setup(tmp_path)
    s.connection.bus.inner.arm.add_gripper(8, part_mm=40.0)
    yield s
    s.close()


@pytest.fixture
def client(setup):
    with TestClient(setup.app(), base_url=LOCAL, raise_server_exceptions=False) as c:
        take_control(c)
        yield c


def sent_to_gripper(setup) -> int:
    """SetExtended (0x08) and SetMotion (0x0B) requests to the gripper: what changes it."""
    return sum(1 for frame in list(setup.wire.frames)
               if frame[1] == GRIPPER_SET and frame[2][:1] in (b"\x08", b"\x0b"))


def test_grip_and_release_from_the_console(client, setup):
    armed(client)
    state = client.get("/api/v1/gripper").json()
    assert state["name"] == "PG 70" and state["width_mm"] == pytest.approx(70.0)
    r = client.post("/api/v1/gripper/grip", json={"part_width_mm": 40, "force_n": 100})
    assert r.status_code == 200, r.text
    idle(client)
    state = wait_for(lambda: (g := client.get("/api/v1/gripper").json())["holding"] and g)
    assert state["width_mm"] == pytest.approx(40.0, abs=0.1)
    r = client.post("/api/v1/gripper/release", json={"width_mm": 60})
    assert r.status_code == 200, r.text
    idle(client)
    state = wait_for(lambda: (g := client.get("/api/v1/gripper").json())["width_mm"] > 59 and g)
    assert state["holding"] is False


def test_a_grip_force_above_the_limit_is_refused_and_sends_nothing(client, setup):
    armed(client)
    before = sent_to_gripper(setup)
    refused(client.post("/api/v1/gripper/grip", json={"part_width_mm": 40, "force_n": 500}),
            409, "force_n 500 N is above the gripper's limit 200 N")
    refused(client.post("/api/v1/gripper/grip", json={"part_width_mm": 40, "force_n": True}),
            422)
    assert sent_to_gripper(setup) == before


def test_grip_needs_control(setup):
    with TestClient(setup.app(), base_url=LOCAL, raise_server_exceptions=False) as c:
        r = c.post("/api/v1/gripper/grip", json={"part_width_mm": 40, "force_n": 50})
        assert r.status_code in (403, 409), r.text
