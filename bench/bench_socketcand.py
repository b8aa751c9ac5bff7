"""Answer latency through the socketcand simulator (``seqrun sim serve``) with a second
master on the bus, and what a python-can client sees of the stream.

Two python-can socketcand clients on one in-process server (real time):
- the *runner*: a 100 Hz loop of ``read_arm`` (7 pipelined FPosStateDio requests) through
  :class:`~seqrun.powercube.client.PowerCubeClient`, timing each refresh;
- the *watcher*: ``status --watch``'s pattern, 21 requests (ActPos, ActVel, CubeState of
  every module) every ``--period`` seconds, not reading in between.

Reports refresh-time percentiles, refreshes over the 50 ms response timeout, lost answers
(timeouts) of either master, and python-can's "incomplete message" warnings (half
elements at a read boundary). Numbers depend on the machine's load; run it on a quiet one.

Run: ``.venv/bin/python bench/bench_socketcand.py [--seconds 10] [--period 0.2]``
"""

from __future__ import annotations

import argparse
import json
import logging
import statistics
import sys
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import can  # noqa: E402

from seqrun.clock import RealClock  # noqa: E402
from seqrun.errors import ModuleTimeoutError  # noqa: E402
from seqrun.powercube.client import PowerCubeClient  # noqa: E402
from seqrun.powercube.codec import GetParam  # noqa: E402
from seqrun.powercube.protocol import ParamId  # noqa: E402
from seqrun.sim.arm import SimArm  # noqa: E402
from seqrun.sim.network import SimNetwork  # noqa: E402
from seqrun.sim.socketcand import SocketcandServer  # noqa: E402

MODULES = range(1, 8)


class _Count(logging.Handler):
    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.incomplete = 0

    def emit(self, record: logging.LogRecord) -> None:
        if "incomplete" in record.getMessage():
            self.incomplete += 1


def _client(port: int) -> PowerCubeClient:
    bus = can.Bus(interface="socketcand", host="127.0.0.1", port=port, channel="can0",
                  ignore_config=True, tcp_tune=True)
    return PowerCubeClient(bus, RealClock(), response_timeout=0.05)


def run(seconds: float, period: float) -> dict:
    counter = _Count()
    logging.getLogger("can").addHandler(counter)
    logging.getLogger("can").propagate = False
    clock = RealClock()
    server = SocketcandServer(SimNetwork(clock, SimArm(clock), spin_window=0.0), port=0)
    server.start()
    runner, watcher = _client(server.port), _client(server.port)
    stop = time.monotonic() + seconds
    watcher_lost = [0, 0]  # refreshes, refreshes with a lost answer

    def watch() -> None:
        requests = [GetParam(m, p) for m in MODULES
                    for p in (ParamId.ACT_POS, ParamId.ACT_VEL, ParamId.CUBE_STATE)]
        while time.monotonic() < stop:
            acks = watcher.transact_partial(requests)
            watcher_lost[0] += 1
            watcher_lost[1] += any(a is None for a in acks)
            time.sleep(period)

    thread = threading.Thread(target=watch, daemon=True)
    thread.start()
    times, timeouts = [], 0
    next_cycle = time.monotonic()
    while time.monotonic() < stop:
        start = time.perf_counter()
        try:
            runner.read_arm(MODULES)
            times.append(time.perf_counter() - start)
        except ModuleTimeoutError:
            timeouts += 1
        next_cycle += 0.01
        time.sleep(max(0.0, next_cycle - time.monotonic()))
    thread.join()
    for client in (runner, watcher):
        client.bus.shutdown()
    server.shutdown()
    times.sort()
    ms = [1000 * t for t in times]
    return {"seconds": seconds, "watch_period_s": period, "runner_refreshes": len(ms),
            "runner_timeouts": timeouts,
            "runner_refresh_ms": {"p50": round(statistics.median(ms), 3),
                                  "p99": round(ms[int(0.99 * (len(ms) - 1))], 3),
                                  "max": round(ms[-1], 3)} if ms else None,
            "runner_refreshes_over_50ms": sum(m > 50 for m in ms),
            "watcher_refreshes": watcher_lost[0],
            "watcher_refreshes_with_a_lost_answer": watcher_lost[1],
            "incomplete_message_warnings": counter.incomplete}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--period", type=float, default=0.2, help="watcher period, s")
    parser.add_argument("--out", type=Path, help="also write the result as JSON here")
    args = parser.parse_args(argv)
    result = run(args.seconds, args.period)
    text = json.dumps(result, indent=2)
    print(text)
    if args.out:
        args.out.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
