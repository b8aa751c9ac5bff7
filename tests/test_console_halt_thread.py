"""STOP's Halt runs on a thread of its own (:func:`seqrun.console.app.halt_on_thread`); when
the web server stops before that thread ends, the Halt is still done and the thread ends
quietly (it used to raise "Event loop is closed" in the thread)."""

from __future__ import annotations

import asyncio
import logging
import threading

from seqrun.console.app import halt_on_thread


def test_a_halt_that_ends_after_the_server_stopped_ends_quietly(monkeypatch, caplog):
    release, halted = threading.Event(), []
    unhandled: list[threading.ExceptHookArgs] = []
    monkeypatch.setattr(threading, "excepthook", unhandled.append)

    def halt(reason: str) -> dict:
        release.wait(5)
        halted.append(reason)
        return {"sent": True}

    def server() -> None:  # a thread of its own: the test's thread may run a loop already
        loop = asyncio.new_event_loop()
        request = loop.create_task(halt_on_thread(halt, "STOP", "console-halt-test"))
        loop.run_until_complete(asyncio.sleep(0.05))   # the thread is under way
        request.cancel()
        loop.run_until_complete(asyncio.gather(request, return_exceptions=True))
        loop.close()                                   # the server has stopped

    serving = threading.Thread(target=server)
    serving.start()
    serving.join(5)
    (thread,) = [t for t in threading.enumerate() if t.name == "console-halt-test"]
    with caplog.at_level(logging.WARNING, logger="seqrun.console.app"):
        release.set()
        thread.join(5)
    assert halted == ["STOP"]                      # the Halt itself was done
    assert unhandled == []
    assert "console-halt-test ended after the server stopped" in caplog.text
