"""Which Foxglove clients connect to ``--foxglove`` (docs/ros2.md, "Which Foxglove clients
connect"): the foxglove-sdk server speaks ``foxglove.sdk.v1`` (and ``foxglove.sdk.v1.1``)
only; a client that offers only the older ``foxglove.websocket.v1`` gets HTTP 400 with the
SDK's one-line reason, one that offers both is served ``foxglove.sdk.v1``."""

from __future__ import annotations

import socket

import pytest

pytest.importorskip("foxglove", reason="foxglove-sdk is the test extra's")

from consolekit import console_setup  # noqa: E402
from projecttree import ROOT  # noqa: E402

from seqrun.foxglove.live import FoxgloveLive  # noqa: E402


@pytest.fixture(scope="module")
def port(tmp_path_factory):
    setup = console_setup(tmp_path_factory.mktemp("fox"))
    server = FoxgloveLive(setup.session, setup.arm, port=0)
    yield server.port
    server.close()
    setup.close()


def handshake(port: int, offered: str | None) -> tuple[str, str | None, bytes]:
    """A WebSocket upgrade offering ``offered`` subprotocols: (status line, the protocol the
    server chose, the start of what followed)."""
    head = (f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
            "Connection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
            "Sec-WebSocket-Version: 13\r\n"
            + (f"Sec-WebSocket-Protocol: {offered}\r\n" if offered else "") + "\r\n")
    with socket.create_connection(("127.0.0.1", port), timeout=5) as sock:
        sock.sendall(head.encode())
        data = b""
        while b"\r\n\r\n" not in data:
            chunk = sock.recv(4096)
            if not chunk:
                break
            data += chunk
        header, _, rest = data.partition(b"\r\n\r\n")
        if header.startswith(b"HTTP/1.1 400") and not rest:
            rest = sock.recv(4096)
    lines = header.decode("latin-1").split("\r\n")
    chosen = next((line.split(":", 1)[1].strip() for line in lines[1:]
                   if line.lower().startswith("sec-websocket-protocol:")), None)
    return lines[0], chosen, rest


@pytest.mark.parametrize("offered", ["foxglove.sdk.v1", "foxglove.sdk.v1.1"])
def test_a_client_offering_the_sdk_subprotocol_is_served(port, offered):
    status, chosen, _ = handshake(port, offered)
    assert status == "HTTP/1.1 101 Switching Protocols" and chosen == offered


def test_a_client_offering_both_gets_the_sdk_subprotocol(port):
    status, chosen, _ = handshake(port, "foxglove.websocket.v1, foxglove.sdk.v1")
    assert status.startswith("HTTP/1.1 101") and chosen == "foxglove.sdk.v1"


@pytest.mark.parametrize("offered", ["foxglove.websocket.v1", None])
def test_an_older_client_gets_http_400_and_the_sdks_reason(port, offered):
    status, chosen, body = handshake(port, offered)
    assert status == "HTTP/1.1 400 Bad Request" and chosen is None
    assert b"Missing expected sec-websocket-protocol header" in body


def test_the_docs_name_what_the_server_speaks():
    text = " ".join((ROOT / "docs" / "ros2.md").read_text(encoding="utf-8").split())
    assert "`foxglove.sdk.v1`" in text and "HTTP 400" in text
    assert "Missing expected sec-websocket-protocol header" in text
