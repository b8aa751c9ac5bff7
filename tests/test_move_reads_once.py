"""A move reads the arm once before it plans (issue 25): the reading a step finds its
target from is the one the move plans from and checks, never a second round of reads
right after it."""

from __future__ import annotations

import pytest

from projecttree import ROOT
from seqrun.arm.description import load_arm
from seqrun.clock import VirtualClock
from seqrun.executor import Executor
from seqrun.sequence.checks import check_from_arm
from seqrun.powercube.client import PowerCubeClient
from seqrun.sequence.loader import load_sequence
from seqrun.sim.bus import SimBus

FPOS_READ = bytes.fromhex("0a62")   # GetExtended FPosStateDio
SET_MOTION = 0x0B


def frames_per_step(sequence: str) -> dict[int, list[tuple[int, bytes]]]:
    """The requests each step sent (id, data), by step number."""
    loaded = load_sequence(ROOT / "sequences" / f"{sequence}.yaml")
    arm = load_arm(loaded.arm_path)
    clock = VirtualClock()
    bus = SimBus(channel=f"reads-once-{sequence}", clock=clock)
    step = {"n": 0}
    sent: dict[int, list[tuple[int, bytes]]] = {}
    try:
        client = PowerCubeClient(bus, clock)
        client.add_frame_listener(lambda m: m.is_rx or sent.setdefault(step["n"], []).append(
            (m.arbitration_id, bytes(m.data))))

        def on_event(event) -> None:
            if event.type == "step_started":
                step["n"] = event.step

        executor = Executor(client, arm, clock, sequence_check=check_from_arm,
                            poses_dir=loaded.poses_dir, dry_run=True,
                            cycle_hz=10, confirm=lambda prompt: True, listeners=[on_event])
        assert executor.run(loaded).exit_code == 0
    finally:
        bus.shutdown()
    return sent


@pytest.mark.parametrize("sequence, moves", [("opsafe", (5, 6))])
def test_a_move_reads_every_module_once_before_its_first_motion_command(sequence, moves):
    sent = frames_per_step(sequence)
    for number in moves:
        before_motion = []
        for can_id, data in sent[number]:
            if data[:1] == bytes([SET_MOTION]):
                break
            before_motion.append((can_id, data))
        reads = [can_id for can_id, data in before_motion if data == FPOS_READ]
        assert sorted(reads) == [0x0C0 + m for m in range(1, 8)], (number, before_motion)
