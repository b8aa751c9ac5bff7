"""Foxglove live against the 100 Hz loop: a run with the server off, and on with a client.

Each run is ``seqrun run sequences/NAME.yaml --sim --yes`` in an arm session, in process, on
the simulator in real time (as ``seqrun run`` runs it). In the "on" runs the session is
served by :class:`seqrun.foxglove.live.FoxgloveLive` on 127.0.0.1 (a free port) and a
client in another process (tests/foxglove_client.py: the foxglove.sdk.v1 protocol)
subscribes to every channel and reads everything for the whole run, as a Foxglove app
showing the arm, plots and the log does. Runs alternate, the order flipping every pair.
The loop period is the spacing of consecutive ``setpoint`` events within a move.

Reported per mode (all runs pooled): p50 / p99 / max period, p99 period error, periods
>= 12 ms, the process's CPU seconds per run, and what the client received. Goal: the "on"
row matches the "off" one (p99 within 2 ms).

``--rt-priority N``: the loop's thread at SCHED_FIFO N, the process's other threads at
SCHED_RR 1 (as ``seqrun console --rt-priority N``).

Run: ``python bench/bench_foxglove.py [--pairs 2] [--sequence opsafe] [--rt-priority 10]``
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from loop_pairs import off_on_main, periods  # noqa: E402
from seqrun_runs import RESULTS, ROOT, load_shipped, machine, write_json  # noqa: E402

from seqrun.clock import RealClock  # noqa: E402
from seqrun.service.connection import open_connection  # noqa: E402

CLIENT = """
import json, sys, time
sys.path.insert(0, {tests!r})
from foxglove_client import FoxgloveClient
c = FoxgloveClient({port})
c.subscribe(*c.channels)
print("subscribed", flush=True)
deadline = time.monotonic() + 600
while time.monotonic() < deadline and not sys.stdin.closed:
    try:
        c.pump(lambda: False, timeout=0.5)
    except TimeoutError:
        pass
    except Exception:
        break
    import select
    if select.select([sys.stdin], [], [], 0)[0]:
        break
print(json.dumps({{"messages": sum(len(v) for v in c.data.values()),
                  "bytes": sum(len(p) for v in c.data.values() for _, p in v)}}), flush=True)
"""


def one_run(sequence: str, served: bool) -> dict:
    from seqrun.service import ArmSession

    loaded, arm = load_shipped(sequence)
    connection = open_connection(force_sim=True, clock=RealClock(),
                                 default_bitrate=arm.can.bitrate)
    session = ArmSession(arm, connection, status_hz=0, own_connection=False)
    setpoints: list = []

    def record(event) -> None:
        if event["type"] in ("setpoint", "step_started", "controlled_stop"):
            setpoints.append({"type": event["type"], "t": event["t"],
                              "step": event.get("step")})

    live = client = None
    received: dict = {}
    try:
        if served:
            from seqrun.foxglove.live import FoxgloveLive

            live = FoxgloveLive(session, arm, port=0)
            client = subprocess.Popen(
                [sys.executable, "-c", CLIENT.format(tests=str(ROOT / "tests"),
                                                     port=live.port)],
                stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
            assert client.stdout is not None
            assert client.stdout.readline().strip() == "subscribed"
            time.sleep(0.5)
        with tempfile.TemporaryDirectory() as tmp:
            cpu0 = time.process_time()
            result = session.run_loaded(
                loaded, log_dir=Path(tmp) / "run", confirm=lambda prompt: True,
                html_report=False,
                on_executor=lambda executor: executor.listeners.append(record))
            cpu = time.process_time() - cpu0
        if client is not None:
            out, _ = client.communicate("stop\n", timeout=30)
            received = json.loads(out.strip().splitlines()[-1])
    finally:
        if live is not None:
            live.close()
        session.close()
        connection.close()
    return {"exit_code": result.result.exit_code, "periods": periods(setpoints), "dropped": 0,
            "cpu_s": cpu, "client_received": received}


def main() -> None:
    off_on_main(__doc__.splitlines()[0], one_run, label="Foxglove", key="foxglove",
                extra="client_received", extra_unit="", results=RESULTS / "foxglove.json",
                machine=machine, write_json=write_json)


if __name__ == "__main__":
    main()
