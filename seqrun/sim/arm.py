"""SimArm: the seven simulated modules of an LWA 3 behind one CAN connector, plus faults.

:meth:`SimArm.handle_frame` is what the modules do with one frame from the wire: decode it
with the shared codec (:mod:`seqrun.powercube.codec`), let the addressed module (or every
module, for 0x100) act on it, and return the acknowledges, each ready to be sent
``module_latency`` after the request was received. Frames that are not valid PowerCube
requests — other ids, bad lengths, unknown commands, other modules' acks — are ignored,
as a real module ignores them. A GetExtended ``[0x0A, par]`` sent on the SET identifier
0x0E0+m (the KTH driver looks for module 1 that way at every start) is answered like one
on the GET identifier, on 0x0A0+m, as real modules do.

Faults (:mod:`seqrun.sim.faults`) are applied when the arm's time passes their ``at``
(seconds after the arm was created): the module is first simulated up to that instant,
so a tow error at 2.5 s stops the joint where it was at 2.5 s, whoever looks first.

Thread-safe: every public method holds one lock.
"""

from __future__ import annotations

import random
import threading
from collections.abc import Iterable, Mapping, Sequence
from typing import NamedTuple

from seqrun.clock import Clock
from seqrun.errors import CodecError
from seqrun.powercube.codec import (
    Ack,
    BroadcastRequest,
    CommandAck,
    decode_request,
    encode,
)
from seqrun.powercube.protocol import GET_BASE, SET_BASE, ParamId, StateFlag
from seqrun.sim.faults import Fault, parse_faults
from seqrun.sim.module import ModuleOptions, SimModule

#: Builds a Reply without the named tuple's Python-level ``__new__`` (once per frame).
_new_tuple = tuple.__new__
#: Seconds between the end of a request frame and its acknowledge being ready to send [I].
DEFAULT_MODULE_LATENCY = 100e-6
_GET_EXTENDED = 0x0A
_GET_EXTENDED_BYTE = bytes([_GET_EXTENDED])


def draw_serial_base() -> int:
    """A serial base of its own for one simulated arm: ``NNNNN00`` (module M: ``+ M``)."""
    return random.SystemRandom().randrange(10_000, 100_000) * 100


class Reply(NamedTuple):
    """An acknowledge a module wants to put on the bus from ``ready_at`` on."""

    module: int
    can_id: int
    data: bytes
    ready_at: float


class SimArm:
    """The simulated modules (ids ``modules``, default 1..7), all at position 0 (Park).

    :param clock: the time base; ``at`` of faults counts from ``clock.now()`` at creation.
    :param faults: :class:`~seqrun.sim.faults.Fault` objects or spec strings.
    :param module_latency: request-to-ack processing time of every module (seconds).
    :param seed: seeds the random loss of ``drop_acks`` faults (per module, so one
        module's losses do not depend on the traffic of another).
    :param options: behaviours no source confirms, see :class:`~seqrun.sim.module.ModuleOptions`.
    :param positions: start positions (rad, module coordinates) instead of all zeros.
    :param power_on_pose: the pose the arm physically stands in at power-on (the modules'
        zeros: they read 0 wherever they were powered off). The encoders read the same
        either way; this names where that is, for the zero reference (``--power-on-at``).
    :param serials: serial numbers (DefCubeSerial) by module id, for the modules it names;
        the others say ``options.serial_base + id``, or with base 0 a base drawn for this
        arm alone (:func:`draw_serial_base`).
    """

    def __init__(self, clock: Clock, modules: Iterable[int] = range(1, 8),
                 faults: Iterable[Fault | str] | str = (), *,
                 module_latency: float = DEFAULT_MODULE_LATENCY, seed: int = 0,
                 options: ModuleOptions | None = None,
                 positions: Mapping[int, float] | Sequence[float] | None = None,
                 power_on_pose: str = "park",
                 serials: Mapping[int, int] | None = None) -> None:
        if module_latency < 0:
            raise ValueError(f"module_latency must be >= 0, got {module_latency}")
        self.clock = clock
        self.start_time = clock.now()
        self.module_latency = module_latency
        self.seed = seed
        #: Where the simulated arm physically stood when it was powered on (its zeros).
        self.power_on_pose = power_on_pose
        self.options = options or ModuleOptions()
        self._lock = threading.RLock()
        modules = list(modules)
        base = self.options.serial_base or draw_serial_base()
        if not 0 <= base <= 0xFFFFFFFF - max(modules, default=0):
            raise ValueError(f"serial_base {base}: serials are 32-bit (0 < base + module "
                             "< 2^32)")
        given = dict(serials or {})
        self._modules = {m: SimModule(m, clock, options=self.options, parameters={
            ParamId.DEF_CUBE_SERIAL: given.pop(m, base + m)}) for m in modules}
        #: The gripper's module id (``options.gripper_module``), None without one.
        self.gripper_id: int | None = None
        self._serial_base = base
        if self.options.gripper_module:
            self._add_gripper(self.options.gripper_module, self.options.gripper_part_mm,
                              given.pop(self.options.gripper_module, None))
        if given:
            raise ValueError(f"serials for module(s) {sorted(given)}: the simulated arm has "
                             f"modules {sorted(self._modules)}")
        if not self._modules:
            raise ValueError("a simulated arm needs at least one module")
        self._pending: list[Fault] = []
        self._silent: set[int] = set()  # no_ack
        self._drop_rate: dict[int, float] = {}
        self._rng = {m: random.Random(f"{seed}:{m}") for m in self._modules}
        #: Acknowledges each module produced that have not been sent on the wire yet
        #: (``drop_request_while_busy``).
        self._unsent_acks: dict[int, int] = {m: 0 for m in self._modules}
        #: module -> (its last acknowledge, its frame): modules hand out the same immutable
        #: acknowledge object again while nothing changed (a module at rest read every cycle).
        self._encoded: dict[int, tuple[Ack, int, bytes]] = {}
        #: Requests dropped because their module was busy: (time, module, can_id, data).
        self.dropped_while_busy: list[tuple[float, int, int, bytes]] = []
        #: Every fault applied so far, with the time it was applied.
        self.applied_faults: list[tuple[float, Fault]] = []
        if positions is not None:
            self.set_positions(positions)
        for fault in parse_faults(faults):
            self.inject(fault)

    # -- inspection and set-up ------------------------------------------------------------

    def add_gripper(self, module_id: int, part_mm: float = 0.0) -> None:
        """Give the arm a gripper module (PG 70 model) at ``module_id`` with a part of
        ``part_mm`` between its jaws (0: none): the arm file's gripper on the built-in
        simulator. Nothing changes when it has one at that id already."""
        with self._lock:
            if self.gripper_id == module_id:
                return
            if self.gripper_id is not None:
                raise ValueError(f"the simulated arm has a gripper at {self.gripper_id}")
            self._add_gripper(module_id, part_mm, None)
            self._rng[module_id] = random.Random(f"{self.seed}:{module_id}")
            self._unsent_acks[module_id] = 0

    def _add_gripper(self, module_id: int, part_mm: float, serial: int | None) -> None:
        from seqrun.sim.gripper import SimGripper

        if module_id in self._modules or not 1 <= module_id <= 31:
            raise ValueError(f"gripper_module {module_id}: a joint's id or not 1..31")
        self._modules[module_id] = SimGripper(
            module_id, self.clock, part_m=part_mm / 1000.0, options=self.options,
            parameters={ParamId.DEF_CUBE_SERIAL: serial if serial is not None
                        else self._serial_base + module_id})
        self.gripper_id = module_id

    @property
    def serials(self) -> dict[int, int]:
        """What each module says its serial number is (DefCubeSerial), by module id."""
        serials = {}
        with self._lock:
            for m, module in sorted(self._modules.items()):
                serial = module.parameter(ParamId.DEF_CUBE_SERIAL)
                assert isinstance(serial, int)  # (a u32 parameter)
                serials[m] = serial
        return serials

    @property
    def module_ids(self) -> list[int]:
        return sorted(self._modules)

    def module(self, module_id: int) -> SimModule:
        """The simulated module ``module_id`` (for tests: state, parameters, position).

        Faults due by now are applied first; a fault that becomes due later reaches the
        module only through the arm (any arm method or frame), so look through the arm
        after letting time pass.
        """
        with self._lock:
            self._now(None)
            try:
                return self._modules[module_id]
            except KeyError:
                raise KeyError(f"the simulated arm has no module {module_id} "
                               f"(modules {self.module_ids})") from None

    def positions(self, t: float | None = None) -> dict[int, float]:
        """Actual joint positions (rad, module coordinates) at ``t`` (default now)."""
        with self._lock:
            t = self._now(t)
            return {m: module.position(t) for m, module in sorted(self._modules.items())}

    def states(self, t: float | None = None) -> dict[int, StateFlag]:
        """State words at ``t`` (default now)."""
        with self._lock:
            t = self._now(t)
            return {m: module.state(t) for m, module in sorted(self._modules.items())}

    def set_positions(self, positions: Mapping[int, float] | Sequence[float]) -> None:
        """Put joints at rest at the given positions (rad), e.g. to start from a pose.

        A sequence lists the modules in id order; a mapping names them.
        """
        with self._lock:
            if not isinstance(positions, Mapping):
                values = list(positions)
                joints = [m for m in self.module_ids if m != self.gripper_id]
                if len(values) != len(joints):
                    raise ValueError(f"expected {len(joints)} positions, "
                                     f"got {len(values)}")
                positions = dict(zip(joints, values))
            t = self._now(None)
            for module_id, position in positions.items():
                if module_id not in self._modules:
                    raise KeyError(f"the simulated arm has no module {module_id}")
                self._modules[module_id].set_position(float(position), t)

    # -- faults ---------------------------------------------------------------------------

    def inject(self, fault: Fault | str) -> None:
        """Schedule a fault (``at`` seconds after the arm's start); a time already passed
        applies it now."""
        (fault,) = parse_faults(fault)
        if fault.module is not None and fault.module not in self._modules:
            raise ValueError(f"fault {fault.spec}: the simulated arm has no module "
                             f"{fault.module} (modules {self.module_ids})")
        with self._lock:
            self._pending.append(fault)
            self._pending.sort(key=lambda f: f.at)
            self._apply_due_faults(self.clock.now())

    def _apply_due_faults(self, t: float) -> None:
        while self._pending and self.start_time + self._pending[0].at <= t:
            fault = self._pending.pop(0)
            when = self.start_time + fault.at
            targets = self.module_ids if fault.module is None else [fault.module]
            for module_id in targets:
                self._modules[module_id].inject(fault.kind, when)
                if fault.kind == "no_ack":
                    self._silent.add(module_id)
                elif fault.kind == "drop_acks":
                    self._drop_rate[module_id] = float(fault.rate or 0.0)
            self.applied_faults.append((when, fault))

    def _now(self, t: float | None) -> float:
        t = self.clock.now() if t is None else t
        self._apply_due_faults(t)
        return t

    # -- the wire -------------------------------------------------------------------------

    def handle_frame(self, can_id: int, data: bytes, t: float | None = None) -> list[Reply]:
        """The modules receive one standard data frame (fully received at ``t``).

        Returns the acknowledges, in the order the modules produce them.
        """
        with self._lock:
            # self._now(t), without its two calls when no fault is pending (every frame)
            if t is None:
                t = self.clock.now()
            if self._pending:
                self._apply_due_faults(t)
            if SET_BASE <= can_id < SET_BASE + 0x20 and data[:1] == _GET_EXTENDED_BYTE:
                can_id = GET_BASE + (can_id - SET_BASE)  # a GetExtended on the SET id
            try:
                request = decode_request(can_id, data)
            except CodecError:
                return []  # not for us, or not PowerCube: a real module ignores it
            if isinstance(request, BroadcastRequest):
                for each in self._modules.values():
                    each.handle(request, t)  # never acknowledged
                return []
            module = self._modules.get(request.module)
            if module is None:
                return []
            if self.options.drop_request_while_busy and self._unsent_acks[request.module]:
                self.dropped_while_busy.append((t, request.module, can_id, bytes(data)))
                return []
            ack = module.handle(request, t)
            if ack is None or ((self._silent or self._drop_rate)
                               and not self._ack_survives(request.module)):
                return []
            self._unsent_acks[request.module] += 1
            encoded = self._encoded.get(request.module)
            if encoded is not None and encoded[0] is ack:
                _, ack_id, ack_data = encoded  # the same acknowledge object as last time
            else:
                ack_id, ack_data = encode(ack)
                self._encoded[request.module] = (ack, ack_id, ack_data)
            if isinstance(ack, CommandAck) and not self.options.command_ack_trailer:
                ack_data = ack_data[:1]
            return [_new_tuple(Reply, (request.module, ack_id, ack_data,
                                       t + self.module_latency))]

    def ack_sent(self, module_id: int) -> None:
        """The wire reports that an acknowledge of ``module_id`` has been sent (delivered):
        the module is no longer busy."""
        with self._lock:
            if self._unsent_acks.get(module_id):
                self._unsent_acks[module_id] -= 1

    def _ack_survives(self, module_id: int) -> bool:
        if module_id in self._silent:
            return False
        rate = self._drop_rate.get(module_id)
        return rate is None or self._rng[module_id].random() >= rate
