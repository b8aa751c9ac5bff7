"""The dry run's ceiling: how fast it could be if the simulator, the wire and the client
cost nothing.

Runs the real executor (plan sampling, checks of every reading, guards and link volumes,
following error, events, tracking) on a VirtualClock at the arm file's loop rate, as
``seqrun validate`` does, four ways, alternating run by run in one process (same load):

- ``real``: the dry run as it is (SimPort, simulated wire, client, driver, modules);
- ``modules``: a free wire and client (:class:`FreeWireClient`): every request handed to
  the simulated modules at once, its acknowledge decoded and matched; the bound of any
  cheaper exchange (a cycle-level one included);
- ``law``: an *ideal* driver (:class:`IdealDriver`): every cycle and reading answered at
  once, without a frame, from the plan (the joints exactly where the plan says, every
  module at rest or in motion as the plan says), the setpoint law's requests still built
  and thrown away;
- ``ideal``: the ideal driver alone: the executor's own per-cycle cost.

The free wire and the ideal driver are bench-only bounds, not simulators: their figures
are not the run's (no wire time, no following error), and what happens outside the
stream (reset, home, limits, broadcasts) still goes over the simulated wire. Fault cases
are out of scope (a request without an answer stops the bench). The runs here use a bare
executor, as ``perf_dryrun.py`` does (no foreign-frame watch, no run log).

Run: ``.venv/bin/python bench/dryrun_ceiling.py [--runs 9] [--sequence FILE ...]
[--profile real|modules|law|ideal]``
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from seqrun.arm.description import load_arm
from seqrun.clock import VirtualClock
from seqrun.drivers.base import JointReading
from seqrun.drivers.powercube.driver import PowerCubeDriver
from seqrun.executor import Executor
from seqrun.powercube.client import PowerCubeClient
from seqrun.powercube.codec import BroadcastRequest, decode_ack, encode
from seqrun.powercube.protocol import ShortState
from seqrun.sequence.checks import check_from_arm
from seqrun.sequence.loader import load_sequence
from seqrun.sim.port import SimPort

_AT_REST = ShortState.RAMP_END
_MOVING = ShortState.MOTION


class FreeWireClient(PowerCubeClient):
    """The client with a free wire: each addressed request of an exchange is handed to the
    simulated arm at once (encoded, ``SimArm.handle_frame``), its acknowledge decoded and
    matched, the clock advanced by :attr:`PAIR_S` per pair. Exchanges with a broadcast
    take the real wire; a request without an answer stops the bench. What is left of a dry run is what a cycle-level
    exchange cannot save: the executor, the driver, the codec and the modules' physics."""

    #: Virtual seconds per request/acknowledge pair (about what the pipelined wire takes).
    PAIR_S = 150e-6

    def _exchange(self, requests, timeout, *, raise_on_timeout, on_ack=None):
        if any(isinstance(r, BroadcastRequest) for r in requests):
            return super()._exchange(requests, timeout, raise_on_timeout=raise_on_timeout,
                                     on_ack=on_ack)
        arm = self.bus.arm
        clock = self.clock
        network = self.bus.network
        while (due := network._next_event_time()) is not None:  # a broadcast still queued
            if due > clock.now():
                clock.sleep_until(due)
            network.run_until()
        results: list = []
        times: list = []
        for request in requests:
            can_id, data = encode(request)
            replies = arm.handle_frame(can_id, data, clock.now())
            clock.sleep_until(clock.now() + self.PAIR_S)
            if not replies:
                raise SystemExit("free wire: a request got no answer (a fault case: use "
                                 "the real dry run)")
            (reply,) = replies
            arm.ack_sent(reply.module)
            ack = decode_ack(reply.can_id, reply.data)
            results.append(ack)
            times.append(clock.now())
            self.last_ack_times = times
            if on_ack is not None:
                on_ack(request, ack)
        return results


class IdealDriver(PowerCubeDriver):
    """The PowerCube driver with a free wire: cycles and readings answered at once from
    the plan (see the module docstring)."""

    def __init__(self, client, arm, *, law: bool) -> None:
        super().__init__(client, arm)
        self.run_law = law
        self._deg: np.ndarray | None = None

    def _reading(self, moving_modules: frozenset[int] = frozenset()) -> JointReading:
        now = self.clock.now()
        states = {m: (_MOVING if m in moving_modules else _AT_REST) for m in self.modules}
        return JointReading(self._deg.copy(), states,  # type: ignore[union-attr]
                            np.full(len(self.modules), now))

    def read(self) -> JointReading:
        if self._deg is None:  # the first reading (preflight): from the simulated arm
            reading = super().read()
            self._deg = reading.positions_deg.copy()
            return reading
        return self._reading()

    def cycle(self, plan, t, moving, measured_deg) -> JointReading:
        if self.run_law:
            law = self._law
            assert law is not None
            law.cycle(plan, t, moving, measured_deg)  # built and thrown away
        pos, _, _ = plan.at(t)
        deg = np.degrees(pos)
        assert self._deg is not None
        self._deg[moving] = deg[moving]
        in_motion = frozenset(self.modules[i] for i in moving) if t < plan.duration \
            else frozenset()
        return self._reading(in_motion)


def one(loaded, arm, i: int, mode: str) -> tuple[float, float, float]:
    """(simulated s, thread CPU s, wall s) of one dry run; ``mode``: real | modules | law |
    ideal."""
    clock = VirtualClock()
    # (the simulator's python-can-free port, as ``seqrun validate`` opens it)
    bus = SimPort(f"ceiling{i}-{mode}", clock=clock)
    client = (FreeWireClient if mode == "modules" else PowerCubeClient)(bus, clock)
    driver = (client if mode in ("real", "modules")
              else IdealDriver(client, arm, law=mode == "law"))
    ex = Executor(driver, arm, clock, sequence_check=check_from_arm,
                  poses_dir=loaded.poses_dir, dry_run=True, cycle_hz=arm.control.cycle_hz)
    w, c = time.perf_counter(), time.thread_time()
    res = ex.run(loaded)
    w, c = time.perf_counter() - w, time.thread_time() - c
    bus.shutdown()
    if res.exit_code != 0:
        raise SystemExit(f"{loaded.path} ({mode}): {res.status} {res.message}")
    return res.duration_s, c, w


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=9)
    parser.add_argument("--sequence", action="append", default=None)
    parser.add_argument("--profile", choices=("real", "modules", "law", "ideal"), default=None,
                        help="cProfile one run of this mode (top 30 by tottime)")
    args = parser.parse_args()
    if args.profile:
        import cProfile
        import pstats

        loaded = load_sequence((args.sequence or ["sequences/opsafe.yaml"])[0])
        arm = load_arm(loaded.arm_path)
        one(loaded, arm, 0, args.profile)
        profiler = cProfile.Profile()
        profiler.enable()
        one(loaded, arm, 1, args.profile)
        profiler.disable()
        pstats.Stats(profiler).sort_stats("tottime").print_stats(30)
        return 0
    modes = ("real", "modules", "law", "ideal")
    labels = {"real": "the dry run (simulator, wire, client)",
              "modules": "free wire and client: executor .. modules",
              "law": "ceiling: executor + setpoint law",
              "ideal": "ceiling: executor only"}
    loads = [os.getloadavg()[0]]
    for sequence in args.sequence or ["sequences/opsafe.yaml", "sequences/totem.yaml"]:
        loaded = load_sequence(sequence)
        arm = load_arm(loaded.arm_path)
        for mode in modes:
            one(loaded, arm, 0, mode)  # warm-up
        cpu: dict[str, list[float]] = {m: [] for m in modes}
        simulated: dict[str, float] = {}
        for i in range(args.runs):
            for mode in modes:
                sim, c, _ = one(loaded, arm, i + 1, mode)
                cpu[mode].append(c)
                simulated[mode] = sim
        loads.append(os.getloadavg()[0])
        cycles = simulated["real"] * arm.control.cycle_hz
        print(f"{sequence} at {arm.control.cycle_hz:g} Hz, {args.runs} runs each "
              f"(median thread CPU):")
        for mode in modes:
            median = statistics.median(cpu[mode])
            print(f"  {labels[mode]:40s} {simulated[mode]:7.3f} s simulated in "
                  f"{median * 1e3:7.1f} ms: {simulated[mode] / median:6.1f}x real time, "
                  f"{median / cycles * 1e6:5.0f} us per cycle")
    print(f"1-minute load {min(loads):.1f}-{max(loads):.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
