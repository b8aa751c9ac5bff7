"""A client of a Foxglove WebSocket server speaking ``foxglove.sdk.v1`` (the protocol's
JSON control messages and binary frames), for the tests: no Foxglove code on this side."""

from __future__ import annotations

import json
import struct
import time
from typing import Any

from websockets.sync.client import connect

SUBPROTOCOL = "foxglove.sdk.v1"


class FoxgloveClient:
    def __init__(self, port: int, *, origin: str | None = None) -> None:
        self._connection = connect(f"ws://127.0.0.1:{port}", subprotocols=[SUBPROTOCOL],
                                   open_timeout=5, origin=origin,  # type: ignore[arg-type]
                                   max_queue=None)
        self.ws = self._connection.__enter__()
        assert self.ws.subprotocol == SUBPROTOCOL
        self.info: dict[str, Any] = {}
        self.channels: dict[str, dict[str, Any]] = {}
        self.services: dict[str, dict[str, Any]] = {}
        self.data: dict[int, list[tuple[int, bytes]]] = {}
        self.replies: dict[int, Any] = {}
        self._subs: dict[str, int] = {}
        self._calls = 0
        self.pump(lambda: self.info and self.channels and self.services)

    def _handle(self, message: str | bytes) -> None:
        if isinstance(message, str):
            body = json.loads(message)
            op = body["op"]
            if op == "serverInfo":
                self.info = body
            elif op == "advertise":
                self.channels.update({c["topic"]: c for c in body["channels"]})
            elif op == "advertiseServices":
                self.services.update({s["name"]: s for s in body["services"]})
            elif op == "serviceCallFailure":
                self.replies[body["callId"]] = ("failure", body["message"])
            return
        op = message[0]
        if op == 0x01:   # message data: subscription id, log time, payload
            sub, log_time = struct.unpack_from("<IQ", message, 1)
            self.data.setdefault(sub, []).append((log_time, bytes(message[13:])))
        elif op == 0x03:   # service call response
            _, call, n = struct.unpack_from("<III", message, 1)
            self.replies[call] = ("ok", json.loads(message[13 + n:]))

    def pump(self, until: Any, timeout: float = 10.0) -> None:
        deadline = time.monotonic() + timeout
        while not until():
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError("the server did not say it in time")
            try:
                self._handle(self.ws.recv(timeout=min(left, 0.2)))
            except TimeoutError:
                pass

    def subscribe(self, *topics: str) -> list[int]:
        subs = []
        for topic in topics:
            sub = self._subs[topic] = len(self._subs) + 1
            subs.append(sub)
            self.ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                {"id": sub, "channelId": self.channels[topic]["id"]}]}))
        return subs

    def messages(self, topic: str, count: int = 1, timeout: float = 10.0) -> list[bytes]:
        sub = self._subs[topic]
        self.pump(lambda: len(self.data.get(sub, ())) >= count, timeout)
        return [payload for _, payload in self.data[sub]]

    def call(self, service: str, request: Any = None, *, raw: bytes | None = None,
             timeout: float = 15.0) -> tuple[str, Any]:
        self._calls += 1
        call = self._calls
        payload = raw if raw is not None else json.dumps(request or {}).encode()
        encoding = b"json"
        self.ws.send(struct.pack("<BIII", 0x02, self.services[service]["id"], call,
                                 len(encoding)) + encoding + payload)
        self.pump(lambda: call in self.replies, timeout)
        return self.replies.pop(call)

    def close(self) -> None:
        self._connection.__exit__(None, None, None)


def protobuf_fields(data: bytes) -> list[tuple[int, Any]]:
    """The (field number, value) pairs of a protobuf message: varints as ints, 64-bit as
    doubles, length-delimited as bytes (enough to read Foxglove's messages here)."""
    out, i = [], 0
    while i < len(data):
        key, i = _varint(data, i)
        field, wire = key >> 3, key & 7
        if wire == 0:
            value, i = _varint(data, i)
        elif wire == 1:
            value, i = struct.unpack_from("<d", data, i)[0], i + 8
        elif wire == 2:
            n, i = _varint(data, i)
            value, i = data[i:i + n], i + n
        elif wire == 5:
            value, i = struct.unpack_from("<f", data, i)[0], i + 4
        else:
            raise ValueError(f"wire type {wire}")
        out.append((field, value))
    return out


def _varint(data: bytes, i: int) -> tuple[int, int]:
    shift = value = 0
    while True:
        b = data[i]
        i += 1
        value |= (b & 0x7F) << shift
        shift += 7
        if not b & 0x80:
            return value, i


def joint_states(payload: bytes) -> dict[str, float]:
    """foxglove.JointStates (timestamp 1, joints 2: name 1, position 2) -> name: position."""
    joints = {}
    for field, value in protobuf_fields(payload):
        if field == 2:
            inner = dict(protobuf_fields(value))
            joints[inner[1].decode()] = inner.get(2, 0.0)
    return joints
