"""socketcand server: what goes over the TCP stream — whole elements, every frame a
client sent (also when it hangs up at once), and an error element for bytes that are not
ASCII."""

from __future__ import annotations

import logging
import re
import socket
import threading
import time

import can
import pytest

from seqrun.clock import RealClock
from seqrun.powercube.codec import GetParam, encode
from seqrun.powercube.protocol import ParamId, StateFlag
from seqrun.sim.arm import SimArm
from seqrun.sim.network import SimNetwork
from seqrun.sim.socketcand import ELEMENT_ALIGN, SocketcandServer, pad_element


@pytest.fixture
def server():
    clock = RealClock()
    network = SimNetwork(clock, SimArm(clock), spin_window=0.0)
    with SocketcandServer(network, port=0, channel="can0") as srv:
        srv.start()
        yield srv


def raw_client(server) -> socket.socket:
    """A socketcand client in raw mode, handshake read (python-can's way: one recv each)."""
    sock = socket.create_connection(("127.0.0.1", server.port), timeout=5)
    assert sock.recv(256) == b"< hi >"
    sock.sendall(b"< open can0 >")
    assert sock.recv(256) == b"< ok >"
    sock.sendall(b"< rawmode >")
    assert sock.recv(256) == b"< ok >"
    return sock


def send_text(request) -> bytes:
    can_id, data = encode(request)
    return (f"< send {can_id:03X} {len(data):X} " + " ".join(f"{b:X}" for b in data)
            + " >").encode()


def load(server, seconds: float) -> threading.Thread:
    """A python-can client asking every module for its position as fast as it can."""
    def drive() -> None:
        with can.Bus(interface="socketcand", host="127.0.0.1", port=server.port,
                     channel="can0", ignore_config=True, tcp_tune=True) as bus:
            stop = time.monotonic() + seconds
            while time.monotonic() < stop:
                for module in range(1, 8):
                    can_id, data = encode(GetParam(module, ParamId.ACT_POS))
                    bus.send(can.Message(arbitration_id=can_id, data=data,
                                         is_extended_id=False))
                got = 0
                while got < 7 and bus.recv(0.2) is not None:
                    got += 1
    thread = threading.Thread(target=drive, daemon=True)
    thread.start()
    return thread


def test_pad_element_aligns_every_element():
    for text in ("< frame 0A1 1700000000.123456 0B0464 >",
                 "< frame 12345678 1700000000.123456 0011223344556677 >", "< echo >",
                 "< error " + "x" * 80 + " >"):
        padded = pad_element(text)
        assert len(padded) % ELEMENT_ALIGN == 0 and padded.lstrip() == text
        assert padded.startswith(" ") or len(text) % ELEMENT_ALIGN == 0


@pytest.mark.slow  # 2 s of real-time flooding
def test_a_slow_reader_never_gets_half_an_element(server):
    """A client reading 1024 bytes at a time (as python-can does) while another floods the
    wire: every read ends exactly at the end of an element."""
    sock = raw_client(server)
    driver = load(server, 2.0)
    reads = partial = elements = 0
    stop = time.monotonic() + 2.0
    while time.monotonic() < stop:
        time.sleep(0.02)  # slow: several kilobytes pile up between reads
        chunk = sock.recv(1024).decode("ascii")
        reads += 1
        elements += chunk.count(">")
        partial += not chunk.rstrip().endswith(">")
        assert not re.search(r"<[^>]*<", chunk), chunk
    driver.join()
    sock.close()
    assert elements > 1000 and reads > 20
    assert partial == 0


@pytest.mark.slow  # 2 s of real-time flooding
def test_python_can_client_logs_no_incomplete_message(server, caplog):
    caplog.set_level(logging.WARNING, logger="can")
    driver = load(server, 2.0)
    with can.Bus(interface="socketcand", host="127.0.0.1", port=server.port,
                 channel="can0", ignore_config=True) as watcher:
        seen = 0
        stop = time.monotonic() + 2.0
        while time.monotonic() < stop:
            time.sleep(0.02)
            while watcher.recv(0) is not None:
                seen += 1
    driver.join()
    assert seen > 1000
    assert [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING] == []


def test_non_ascii_bytes_get_an_error_element_and_the_session_goes_on(server, caplog):
    caplog.set_level(logging.DEBUG)
    sock = raw_client(server)
    sock.sendall("< send 0E1 1 \u00e4 >< \u00fcber >".encode())
    answers = b""
    while answers.count(b">") < 2:
        chunk = sock.recv(1024)
        assert chunk, f"the server closed the session after {answers!r}"
        answers += chunk
    assert re.fullmatch(rb"( *< error [ -=?-~]+ >){2}", answers), answers
    sock.sendall(send_text(GetParam(3, ParamId.DEF_CUBE_VERSION)))  # still served
    reply = sock.recv(1024).decode("ascii")
    assert re.fullmatch(r" *< frame 0A3 \d+\.\d{6} 0A1D3846 >", reply), reply
    sock.close()
    assert "Traceback" not in caplog.text and "UnicodeEncodeError" not in caplog.text


@pytest.mark.slow  # 3 s of real-time flooding
def test_a_client_that_sends_and_hangs_up_at_once_still_gets_its_frames_out(server):
    """seqrun halt from a second terminal: send the Halt broadcast, close. The frame was
    accepted, so it reaches the modules — also when the client closes with unread data
    (the kernel then resets the connection instead of closing it)."""
    driver = load(server, 3.0)
    network = server.network
    try:
        for attempt in range(20):
            command = b"< send 100 2 2 0 >" if attempt % 2 == 0 else b"< send 100 2 0 0 >"
            sock = raw_client(server)
            time.sleep(0.005)  # frames from the other client are waiting unread
            sock.sendall(command)
            sock.close()
            deadline = time.monotonic() + 2.0
            want_halted = attempt % 2 == 0
            while time.monotonic() < deadline:
                network.run_until()
                states = network.arm.states()
                if all(bool(s & StateFlag.HALTED) == want_halted for s in states.values()):
                    break
                time.sleep(0.01)
            else:
                pytest.fail(f"attempt {attempt}: {'halt' if want_halted else 'reset'} lost: "
                            f"{states}")
    finally:
        driver.join()


@pytest.mark.slow
def test_a_client_that_reads_slowly_keeps_its_session(server):
    """A watcher that does not read for a while (its socket buffers fill up) is served
    late, never cut off: it then gets the answers to its next questions. (The server used
    to give up on a write after 0.2 s and close the session; a python-can client does not
    notice a closed session, and each of its later requests timed out.)"""
    with can.Bus(interface="socketcand", host="127.0.0.1", port=server.port,
                 channel="can0", ignore_config=True) as sleeper:
        load(server, 25.0).join()  # 25 s of traffic this client does not read
        while sleeper.recv(0) is not None:
            pass
        can_id, data = encode(GetParam(6, ParamId.DEF_CUBE_VERSION))
        sleeper.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline:
            msg = sleeper.recv(0.5)
            if msg is not None and msg.arbitration_id == 0x0A6:
                break
        else:
            pytest.fail("no answer: the server closed the session of a slow reader")
