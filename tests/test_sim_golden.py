"""Golden traces of the simulator: performance work on the simulated wire, the modules,
the codec, the client or the planner must not change a single frame or timestamp.

Two scenarios, each digested (SHA-256) and compared with ``tests/data/golden/``:

- ``opsafe``: ``sequences/opsafe.yaml`` through the real executor on a VirtualClock (as
  ``bench/perf_dryrun.py`` and the dry run drive it), with a fixed seed;
- ``client``: a fixed script of client calls (reset, home, ramps, steps, velocity mode,
  pipelined arm reads, a timeout) that does not depend on the executor.

Each digest covers every frame the client's frame listener sees (``repr`` of the
timestamp, direction, id, data), every frame delivered on the wire as a passive extra
endpoint receives it (exact delivery timestamp, sender, id, data) and the modules' final
positions and state words. A deliberate behaviour change (of the executor, the sequence,
the arm file or the simulator) needs new goldens::

    SEQRUN_REGEN_GOLDEN=1 .venv/bin/pytest tests/test_sim_golden.py
"""

from __future__ import annotations

import hashlib
import os

import pytest

from projecttree import ROOT
from seqrun.arm.description import load_arm
from seqrun.clock import VirtualClock
from seqrun.executor import Executor
from seqrun.sequence.checks import check_from_arm
from seqrun.powercube.client import PowerCubeClient
from seqrun.powercube.codec import GetParam
from seqrun.powercube.protocol import ParamId
from seqrun.sequence.loader import load_sequence
from seqrun.sim.bus import SimBus

GOLDEN = ROOT / "tests" / "data" / "golden"
SEED = 1234


class _Recorder:
    """Client-side and wire-side traces of one simulated run."""

    def __init__(self, bus: SimBus, client: PowerCubeClient) -> None:
        self.bus = bus
        self.client_lines: list[str] = []
        self.client_last = 0.0
        self.sniffer = bus.network.attach(name="golden-sniffer")
        client.add_frame_listener(self._on_frame)

    def _on_frame(self, msg) -> None:
        self.client_last = msg.timestamp
        self.client_lines.append(
            f"{msg.timestamp!r} {'rx' if msg.is_rx else 'tx'} {msg.arbitration_id:03X} "
            f"{bytes(msg.data).hex()}")

    def summary(self) -> dict[str, str]:
        clock = self.bus.clock
        wire_lines = []
        wire_last = 0.0
        while (frame := self.sniffer.receive(clock.now())) is not None:
            wire_last = frame.timestamp
            wire_lines.append(f"{frame.timestamp!r} {frame.sender} {frame.can_id:03X} "
                              f"{frame.data.hex()} {int(frame.is_extended)}"
                              f"{int(frame.is_remote)}")
        arm = self.bus.arm
        state_lines = [f"{m} {p!r} {int(arm.states()[m])}" for m, p in arm.positions().items()]
        network = self.bus.network

        def digest(lines: list[str]) -> str:
            return hashlib.sha256("\n".join(lines).encode()).hexdigest()

        return {
            "client_trace_sha256": digest(self.client_lines),
            "client_frames": str(len(self.client_lines)),
            "client_final_timestamp": repr(self.client_last),
            "wire_trace_sha256": digest(wire_lines),
            "wire_frames": str(len(wire_lines)),
            "wire_final_timestamp": repr(wire_last),
            "wire_busy_time": repr(network.busy_time),
            "final_state_sha256": digest(state_lines),
            "final_clock": repr(clock.now()),
        }


def _check(name: str, summary: dict[str, str]) -> None:
    path = GOLDEN / f"{name}_trace.sha256"
    text = "".join(f"{key} {value}\n" for key, value in summary.items())
    if os.environ.get("SEQRUN_REGEN_GOLDEN"):
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
        pytest.skip(f"wrote {path}")
    expected = dict(line.split(" ", 1) for line in path.read_text().splitlines() if line)
    assert summary == expected


def test_opsafe_golden_trace():
    loaded = load_sequence(ROOT / "sequences" / "opsafe.yaml")
    arm = load_arm(loaded.arm_path)
    clock = VirtualClock()
    bus = SimBus(channel="golden-opsafe", clock=clock, seed=SEED)
    try:
        client = PowerCubeClient(bus, clock)
        recorder = _Recorder(bus, client)
        executor = Executor(client, arm, clock, sequence_check=check_from_arm,
                            poses_dir=loaded.poses_dir, dry_run=True,
                            cycle_hz=10)
        result = executor.run(loaded)
        assert result.exit_code == 0, result.message
        summary = recorder.summary()
        summary["duration_s"] = repr(result.duration_s)
    finally:
        bus.shutdown()
    _check("opsafe", summary)


def test_client_golden_trace():
    clock = VirtualClock()
    bus = SimBus(channel="golden-client", clock=clock, seed=SEED,
                 faults=["6:drop_acks=0.5@0.05", "7:no_ack@0.3"])
    try:
        client = PowerCubeClient(bus, clock, watchdog_period=0.02)
        recorder = _Recorder(bus, client)
        modules = range(1, 8)
        client.reset()
        client.home()
        client.read_arm(modules)
        for m in modules:
            client.move_ramp(m, 0.1 * m - 0.35, 0.5 + 0.1 * m, 1.0, ext_ack=m % 2 == 0)
        for _ in range(40):
            client.transact_partial([GetParam(m, ParamId.FPOS_STATE_DIO) for m in modules])
        client.move_velocity(3, -0.4, ext_ack=True)
        client.move_step(4, -0.2, 300, ext_ack=True)
        client.move_step(5, 0.3, 150)
        for i in range(60):
            client.transact_partial([GetParam(m, ParamId.ACT_POS) for m in modules])
            if i % 10 == 0:
                client.move_step(5, 0.3 - 0.01 * i, 80, ext_ack=True)
        client.idle(0.3)
        client.transact_partial([GetParam(m, ParamId.CUBE_STATE) for m in modules])
        client.halt()
        client.idle(0.25)
        summary = recorder.summary()
        summary["client_stats"] = repr((client.stats.frames_sent, client.stats.frames_received,
                                        client.stats.acks_matched,
                                        sorted(client.stats.discarded.items())))
    finally:
        bus.shutdown()
    _check("client", summary)
