"""The bus owner's control socket: JSON lines with "v": 1, ops status and halt."""

from __future__ import annotations

import socket
import threading
import time

import pytest

from seqrun.service.bus_claim import claim_bus, read_holder
from seqrun.service.control_socket import (ask_owner, handle_request, send_request,
                                           serve_control)


@pytest.fixture
def rundir(monkeypatch):
    # Short: a unix socket path has about 100 bytes.
    import shutil
    import tempfile

    folder = tempfile.mkdtemp(prefix="sq", dir="/tmp")
    monkeypatch.setenv("SEQRUN_RUNTIME_DIR", folder)
    yield folder
    shutil.rmtree(folder, ignore_errors=True)


class Owner:
    def __init__(self, halt_delay: float = 0.0) -> None:
        self.halts: list[str] = []
        self.halt_delay = halt_delay

    def status_dict(self) -> dict:
        return {"joints": [{"joint": "j1", "position_deg": 1.5}], "end_effector": None}

    def halt(self, reason: str) -> dict:
        time.sleep(self.halt_delay)
        self.halts.append(reason)
        return {"confirmed": True, "modules_confirmed": [1, 2]}


def test_status_and_halt_through_the_socket_of_the_holder(rundir):
    owner = Owner()
    with claim_bus("socketcan", "can0", "seqrun run a.yaml") as claim:
        server = serve_control(claim, owner)
        assert read_holder("socketcan", "can0").socket == str(server.path)
        reply = ask_owner("socketcan", "can0", "status")
        assert reply["ok"] and reply["v"] == 1
        assert reply["status"]["joints"][0]["position_deg"] == 1.5
        assert reply["holder"]["command"] == "seqrun run a.yaml"
        reply = ask_owner("socketcan", "can0", "halt", reason="seqrun halt (pid 7)")
        assert reply["halt"]["confirmed"] and owner.halts == ["seqrun halt (pid 7)"]
        path = server.path
    # Released with the claim: no socket, nobody to ask.
    assert not path.exists()
    assert ask_owner("socketcan", "can0", "status") is None


def test_nobody_to_ask_when_free_or_the_holder_serves_nothing(rundir):
    assert ask_owner("socketcan", "can0", "status") is None
    with claim_bus("socketcan", "can0", "seqrun reset"):
        assert ask_owner("socketcan", "can0", "status") is None


def test_bad_requests_get_one_error_each():
    owner = Owner()
    assert handle_request(owner, b"not json")["error"] == "not a JSON line"
    assert "version 2 not supported" in handle_request(owner, b'{"v": 2, "op": "status"}')["error"]
    assert "unknown op 'jog'" in handle_request(owner, b'{"v": 1, "op": "jog"}')["error"]
    assert handle_request(owner, b"[1]")["ok"] is False

    class Broken(Owner):
        def status_dict(self):
            raise RuntimeError("no reading yet")

    reply = handle_request(Broken(), b'{"v": 1, "op": "status"}')
    assert reply == {"v": 1, "ok": False, "error": "status failed: RuntimeError: no reading yet"}


def test_a_slow_or_silent_client_never_blocks_another(rundir):
    owner = Owner(halt_delay=1.0)
    with claim_bus("socketcan", "can0", "seqrun run") as claim:
        server = serve_control(claim, owner)
        silent = socket.socket(socket.AF_UNIX)
        silent.connect(str(server.path))       # connects and never says anything
        slow = threading.Thread(target=ask_owner, args=("socketcan", "can0", "halt"))
        slow.start()
        t0 = time.monotonic()
        assert ask_owner("socketcan", "can0", "status")["ok"]
        assert time.monotonic() - t0 < 0.5
        slow.join()
        silent.close()
        assert owner.halts == ["halt from another process"]


def test_an_owner_that_does_not_answer_in_time_is_an_error_not_a_hang(rundir, tmp_path):
    with claim_bus("socketcan", "can0", "seqrun run") as claim:
        serve_control(claim, Owner(halt_delay=2.0))
        t0 = time.monotonic()
        reply = ask_owner("socketcan", "can0", "halt", timeout=0.3)
        assert time.monotonic() - t0 < 1.0
        assert not reply["ok"] and reply["error"].startswith("no answer from pid")
    with pytest.raises(OSError):
        send_request(tmp_path / "nobody.sock", {"op": "status"})


def test_released_with_the_claim_the_accept_thread_has_ended(rundir):
    # A run's control thread must not outlive the run that served it (a console or a soak
    # runs run after run in one process).
    with claim_bus("socketcan", "can0", "seqrun run a.yaml") as claim:
        serve_control(claim, Owner())
        assert any(t.name == "seqrun-control" for t in threading.enumerate())
    assert [t.name for t in threading.enumerate() if t.name == "seqrun-control"] == []
