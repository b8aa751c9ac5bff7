"""The PowerCube driver: the executor's arm-driver calls over a :class:`PowerCubeClient`.

Everything that knows PowerCube frames lives here (or in the client and codec below it):

- reads: FPosStateDio per module, or ActPos + CubeState while that request is in
  quarantine after a lost acknowledge; a lost read is retried once by the other path;
- a control cycle: the setpoint law's requests (:mod:`seqrun.drivers.powercube.setpoints`) plus
  reads of the other modules, pipelined; every acknowledge is looked at as it arrives and
  the first that says NOT_OK ends the cycle at once (:class:`~seqrun.drivers.base.MotionRefused`)
  so that the executor halts before the rest of the batch is collected;
- state words decoded into :class:`~seqrun.drivers.base.JointState` (fault cause named);
- the modules' watchdog: Config read-modify-write and a keeper thread that refreshes only
  while the control loop shows signs of life;
- Halt or Reset confirmed by reading every module's state back (:func:`confirm_command`,
  the one implementation: the executor's emergency Halt and ``seqrun halt|reset``);
- MinPos/MaxPos/MaxVel/MaxAcc read back and written.
"""

from __future__ import annotations

import dataclasses
import math
import threading
from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar

import numpy as np

from seqrun.arm.description import ArmDescription
from seqrun.arm.planner import Limits, MovePlan
from seqrun.drivers.base import (ArmIdentity, ArmPoll, CommandConfirmation, ConfirmedCommand,
                                 CycleState,
                                 EventSink, ForeignTraffic, JointLimits, JointReading,
                                 JointState, LimitValues, MotionRefused)
from seqrun.drivers.powercube.confirm import (DEFAULT_ATTEMPTS, command_and_confirm,
                                              confirm_command)
from seqrun.drivers.powercube.homing import home_and_confirm
from seqrun.drivers.powercube.messages import user_message
from seqrun.drivers.powercube.setpoints import SetpointLaw, setpoint_law
from seqrun.drivers.powercube.states import (FAULT_FLAGS, HOMED_FLAG, cycle_state,
                                             joint_state, short_state)
from seqrun.drivers.powercube.units import ModuleUnits, module_positions
from seqrun.errors import BusError, ModuleTimeoutError, RunAborted
from seqrun.powercube.codec import (BroadcastRequest, GetParam, GetParamAck, MotionExtAck,
                                    Request, SetMotion, SetParam)
from seqrun.powercube.protocol import CommandId, ConfigFlag, ParamId, ShortState, StateFlag

#: float32 on the wire: a read-back equal within this is the value written.
READBACK_TOLERANCE_RAD = 1e-6
#: The state of a joint declared absent (no module on the bus): homed, at rest, no fault.
ABSENT_STATE = dataclasses.replace(joint_state(StateFlag.HOME_OK | StateFlag.RAMP_END),
                                   text="ABSENT (no module)")
ABSENT_SHORT_STATE = ShortState.RAMP_END
#: A current limit reads back as written within this (float32 of a few amperes: 1e-6 A).
READBACK_TOLERANCE_A = 1e-5


def _no_events(type_: str, **data: Any) -> None:
    """Event sink until the executor configures the driver."""


# ---------------------------------------------------------------------- the driver
class _NotOkAcknowledge(Exception):
    """An acknowledge said NOT_OK (raised from inside the exchange to end it at once)."""

    def __init__(self, module: int, state: ShortState) -> None:
        super().__init__(f"module {module}: NOT_OK")
        self.module = module
        self.state = state


_FPOS_STATE_DIO, _CUBE_STATE = ParamId.FPOS_STATE_DIO, ParamId.CUBE_STATE
_ACT_POS = ParamId.ACT_POS
_NOT_OK = int(ShortState.NOT_OK)


def _raise_on_not_ok(request, ack) -> None:
    """``on_ack`` inspector of a move cycle: the first NOT_OK ends the exchange."""
    # (Called for every acknowledge of a move: module constants and plain-int flag tests,
    # since an enum class attribute and IntFlag's ``&`` are Python-level calls.)
    if isinstance(ack, MotionExtAck):
        state = ack.state
    elif isinstance(ack, GetParamAck) and ack.param == _FPOS_STATE_DIO:
        state = ack.value.state
    elif isinstance(ack, GetParamAck) and ack.param == _CUBE_STATE:
        state = short_state(StateFlag(ack.value))
    else:
        return
    if int(state) & _NOT_OK:
        raise _NotOkAcknowledge(ack.module, ShortState(state))


def _describe_request(request) -> str:
    if isinstance(request, SetMotion):
        return f"SetMotion {request.mode.name}"
    if isinstance(request, (SetParam, GetParam)):
        return f"{type(request).__name__} {request.param.name}"
    return type(request).__name__


def _acked(request) -> bool:
    return not isinstance(request, BroadcastRequest)


class PowerCubeDriver:
    """:class:`~seqrun.drivers.base.ArmDriver` over a
    :class:`~seqrun.powercube.client.PowerCubeClient` (module docstring)."""

    #: Idempotent reads are retried this often when an acknowledge is lost (drop_acks).
    READ_RETRIES = 1
    #: Attempts of the HOME_OK reading of :meth:`homed` (a read is idempotent).
    HOMED_ATTEMPTS = 3
    #: Seconds ``confirm("home")`` waits for every module to report HOME_OK at rest (a
    #: PRL homes at once; a module that travels to its home switch takes seconds).
    HOME_TIMEOUT_S = 60.0
    FAULT_FLAGS: ClassVar[frozenset[str]] = FAULT_FLAGS
    HOMED_FLAG: ClassVar[str] = HOMED_FLAG

    def __init__(self, client, arm: ArmDescription, *, echoes_own: bool = False) -> None:
        self.client = client
        self.arm = arm
        self.clock = client.clock
        self.modules: list[int] = arm.module_ids
        self._joints_on_bus(arm)
        self.units = ModuleUnits(arm)
        #: The transport hands this process its own frames back (``receive_own_messages``).
        self.echoes_own = echoes_own
        self.emit: EventSink = _no_events
        self.cycle_s = 1.0 / arm.control.cycle_hz
        self.run_limits = Limits.from_arm(arm)
        self.command_mode: str = arm.control.command_mode
        self._run_law: SetpointLaw | None = None
        self._law: SetpointLaw | None = None
        self._keeper: threading.Thread | None = None
        self._keeper_stop = threading.Event()
        #: What says the control loop is alive (given to :meth:`enable_watchdog`).
        self._alive: Callable[[float], bool] | None = None
        #: The watchdog was armed for a velocity motion (the arm file leaves it off).
        self._velocity_watchdog = False
        #: module -> its FPosStateDio read (see _reads)
        self._fpos_reads: dict[int, GetParam] = {}

    # ------------------------------------------------------------------ the family
    @classmethod
    def open(cls, arm: ArmDescription, connection, *,
             response_timeout_s: float | None = None) -> PowerCubeDriver:
        """The driver of ``arm`` on ``connection`` with a client of its own; frames it
        does not use as answers go into the event log."""
        from seqrun.powercube.client import PowerCubeClient

        client = PowerCubeClient(connection.bus, connection.clock, response_timeout=(
            response_timeout_s if response_timeout_s is not None
            else arm.can.response_timeout_s))
        driver = cls(client, arm, echoes_own=bool(getattr(connection, "echoes_own", False)))
        client.on_discard = driver.on_discard
        return driver

    @staticmethod
    def cycle_state(code: int) -> CycleState:
        return cycle_state(code)

    @classmethod
    def simulator_positions(cls, arm: ArmDescription,
                            joints_deg: Mapping[str, float]) -> dict[int, float]:
        return module_positions(arm, joints_deg)

    def use_arm(self, arm: ArmDescription) -> None:
        self.arm = arm
        self._joints_on_bus(arm)
        self.units = ModuleUnits(arm)

    def _joints_on_bus(self, arm: ArmDescription) -> None:
        """Which modules are on the bus. A joint declared absent (``present: false``) has
        none: nothing is sent to its id; readings give its locked angle and a state of
        "absent" (homed, at rest, no fault), so every reading stays in joint order."""
        #: The modules on the bus (every request goes to one of them).
        self.bus_modules: list[int] = arm.present_module_ids
        self._absent: dict[int, Any] = {j.module: j for j in arm.joints if not j.present}

    def _on_bus(self, modules: Sequence[int]) -> list[int]:
        absent = self._absent
        return [m for m in modules if m not in absent] if absent else list(modules)

    def _absent_module_rad(self, module: int) -> float:
        return self.units.joint_module_rad(module, self._absent[module].locked)

    # ------------------------------------------------------------------ the run
    def configure(self, *, cycle_s: float, run_limits: Limits, command_mode: str,
                  emit: EventSink) -> None:
        self._run_law = self._law = setpoint_law(command_mode, self.arm, cycle_s, run_limits)
        self.cycle_s, self.run_limits, self.command_mode = cycle_s, run_limits, command_mode
        self.emit = emit

    def on_discard(self, msg, reason) -> None:
        """Client callback: a received frame was not used as an answer (stale, foreign,
        malformed); it goes into the event log."""
        self.emit("frame_discarded", can_id=f"0x{msg.arbitration_id:03X}",
                  data=bytes(msg.data).hex(" "), reason=str(getattr(reason, "value", reason)))

    def describe_error(self, exc: BaseException) -> str:
        """``str(exc)``, with a request that got no answer described in user degrees."""
        return user_message(exc, self.arm)

    # ------------------------------------------------------------------ bus helpers
    def transact(self, requests: list, *, idempotent: bool = False) -> list:
        """``client.transact``; ``idempotent`` requests (reads) get one retry."""
        attempts = 1 + (self.READ_RETRIES if idempotent else 0)
        for attempt in range(attempts):
            try:
                return self.client.transact(requests)
            except ModuleTimeoutError as exc:
                if attempt + 1 >= attempts:
                    raise
                self.emit("retry", module=exc.module, what=exc.what)
        raise AssertionError("unreachable")

    def _reads(self, module: int) -> list[GetParam]:
        """How to read a module this cycle: FPosStateDio, or — while that request is in
        quarantine after a lost acknowledge — ActPos and CubeState, which tell the same and
        need not wait for the quarantine."""
        # (the same immutable request every cycle: made once per module)
        primary = self._fpos_reads.get(module)
        if primary is None:
            primary = self._fpos_reads[module] = GetParam(module, _FPOS_STATE_DIO)
        if not self.client.is_tainted(primary):
            return [primary]
        return [GetParam(module, ParamId.ACT_POS), GetParam(module, ParamId.CUBE_STATE)]

    # ------------------------------------------------------------------ reading
    def read(self) -> JointReading:
        """Read position and short state of every module (pipelined, lost reads retried)."""
        return self._cycle([], [])

    def read_state(self, module: int) -> JointState:
        if module in self._absent:
            return ABSENT_STATE
        return joint_state(self.client.read_state(module))

    def read_states(self, modules: Sequence[int] | None = None) -> dict[int, JointState]:
        """CubeState of several modules, pipelined (an absent joint's: "absent")."""
        wanted = self.modules if modules is None else list(modules)
        on_bus = self._on_bus(wanted)
        acks = self.transact([GetParam(m, ParamId.CUBE_STATE) for m in on_bus], idempotent=True)
        states = {m: joint_state(a.value) for m, a in zip(on_bus, acks)}
        return {m: states.get(m, ABSENT_STATE) for m in wanted}

    # ------------------------------------------------------------------ motion
    def start_motion(self, moving: list[int], limits: Limits, *,
                     command_mode: str | None = None) -> None:
        law = self._run_law
        if law is None:
            raise RuntimeError("PowerCubeDriver.configure() was not called")
        if command_mode is not None and command_mode != self.command_mode:
            law = setpoint_law(command_mode, self.arm, self.cycle_s, self.run_limits)
        if command_mode == "velocity":
            # FVEL is open-ended on the module: never without its watchdog (item D.5).
            self._arm_watchdog_for_velocity()
        self._law = law
        start = law.start(moving, limits)
        if start:
            self.transact(start)

    def cycle(self, plan: MovePlan, t: float, moving: list[int],
              measured_deg: np.ndarray) -> JointReading:
        law = self._law
        if law is None:
            raise RuntimeError("PowerCubeDriver.start_motion() was not called")
        reading = self._cycle(law.cycle(plan, t, moving, measured_deg), moving,
                              halt_early=True)
        return reading._replace(holds_at_rad=law.holds_at_rad)

    def end_motion(self) -> None:
        law, self._law = self._law, self._run_law
        finish = getattr(law, "finish", None)  # a velocity law: FVEL 0, never left standing
        if finish is not None:
            requests = finish()
            if requests:
                try:
                    self.transact(requests)
                except BusError as exc:  # a failing motion: the executor's Halt follows
                    self.emit("velocity_zero_failed", error=str(exc))

    def _cycle(self, requests: list[Request], moving: list[int], *,
               halt_early: bool = False) -> JointReading:
        """Send this cycle's motion requests plus reads of the other modules, pipelined.

        A lost answer to a motion command is a fault (we cannot know what the module
        does); a lost read is retried once by the other read path (a read changes nothing
        on the module), so a rare lost acknowledge does not stop the arm.

        With ``halt_early`` (a move), every acknowledge is looked at as it arrives: the
        first one that says NOT_OK raises :class:`MotionRefused` at once, before the rest
        of the batch is collected.
        """
        moving_modules = {self.modules[i] for i in moving}
        reads = [r for m in self.bus_modules if m not in moving_modules for r in self._reads(m)]
        batch: list[Any] = requests + reads   # (addressed requests: every one has a module)
        try:
            acks = self.client.transact_partial(
                batch, on_ack=_raise_on_not_ok if halt_early else None)
        except _NotOkAcknowledge as refused:
            raise MotionRefused(refused.module, refused.state) from None
        times = list(getattr(self.client, "last_ack_times", ()))
        lost = [i for i, (r, a) in enumerate(zip(batch, acks)) if a is None and _acked(r)]
        if any(not isinstance(batch[i], GetParam) for i in lost):
            unanswered = next(batch[i] for i in lost if not isinstance(batch[i], GetParam))
            raise ModuleTimeoutError(unanswered.module, _describe_request(unanswered),
                                     self.client.response_timeout)
        if lost:
            modules = list(dict.fromkeys(batch[i].module for i in lost))
            retry = [r for m in modules for r in self._reads(m)]
            # The retry must go out at once: a request still in quarantine would first
            # wait it out (up to 4 response timeouts) while the joints move unwatched. Both
            # read paths of a module lost within one quarantine is a fault.
            blocked = next((r for r in retry if self.client.is_tainted(r)), None)
            if blocked is not None:
                unanswered = next(batch[i] for i in lost if batch[i].module == blocked.module)
                lost_ack = ModuleTimeoutError(unanswered.module, _describe_request(unanswered),
                                              self.client.response_timeout)
                raise RunAborted("no_acknowledge", f"{lost_ack}; not retried: its other read "
                                 "path is still in quarantine after an earlier lost "
                                 "acknowledge", module=unanswered.module)
            self.emit("retry", modules=modules, what="read")
            batch, acks = batch + retry, acks + self.transact(retry)
            times += list(getattr(self.client, "last_ack_times", ()))
        positions: dict[int, float] = {}
        states: dict[int, ShortState] = {}
        # when each position was answered (the modules measure as they answer)
        answered: dict[int, float | None] = {}
        # (module constants for the enum members: this runs for every acknowledge)
        for ack, at in zip(acks, times + [None] * (len(acks) - len(times))):
            if isinstance(ack, MotionExtAck):
                positions[ack.module], states[ack.module] = ack.position, ack.state
                answered[ack.module] = at
            elif isinstance(ack, GetParamAck):
                if ack.param == _FPOS_STATE_DIO:
                    positions[ack.module] = ack.value.position
                    states[ack.module] = ack.value.state
                    answered[ack.module] = at
                elif ack.param == _ACT_POS:
                    positions[ack.module] = float(ack.value)
                    answered[ack.module] = at
                elif ack.param == _CUBE_STATE:
                    states[ack.module] = short_state(StateFlag(ack.value))
        for module in self._absent:
            positions[module] = self._absent_module_rad(module)
            states[module] = ABSENT_SHORT_STATE
        module_rad = np.array([positions[m] for m in self.modules])
        stamps = [answered.get(m) for m in self.bus_modules]
        if None in stamps:
            at = None
        elif self._absent:   # an absent joint "answers" with the first module on the bus
            at = np.array([answered.get(m, stamps[0]) for m in self.modules], dtype=float)
        else:
            at = np.array(stamps, dtype=float)
        return JointReading(self.units.user_deg(module_rad), states, at)  # type: ignore[arg-type]

    # ------------------------------------------------------------------ commands
    def reset(self, modules: Sequence[int] | None) -> None:
        self._command(self.client.reset, modules)

    def home(self, modules: Sequence[int] | None) -> None:
        self._command(self.client.home, modules)

    def halt(self, modules: Sequence[int] | None) -> None:
        self._command(self.client.halt, modules)

    def _command(self, send: Callable[[int | None], None],
                 modules: Sequence[int] | None) -> None:
        if modules is not None:
            modules = self._on_bus(modules)
        if modules is None:
            send(None)          # one broadcast
        else:
            for module in modules:
                send(module)

    def halt_and_confirm(self) -> CommandConfirmation:
        return confirm_command(self.client, CommandId.HALT, self.bus_modules)

    def halt_now(self, *, wait: bool = True) -> None:
        self.client.halt_now(wait=wait)

    def confirm(self, command: ConfirmedCommand,
                modules: Sequence[int] | None = None,
                attempts: int = DEFAULT_ATTEMPTS) -> CommandConfirmation:
        if command == "home":  # sent once, then read until homed (it may travel)
            wanted = self._on_bus(self.bus_modules if modules is None else modules)
            return home_and_confirm(self.client, wanted,
                                    whole_arm=set(wanted) >= set(self.bus_modules),
                                    timeout_s=self.HOME_TIMEOUT_S)
        return command_and_confirm(self.client, CommandId[command.upper()],
                                   self._on_bus(self.bus_modules if modules is None
                                                else modules),
                                   attempts=attempts)

    # ------------------------------------------------------------------ outside a run
    _STATUS_PARAMS = (ParamId.ACT_POS, ParamId.ACT_VEL, ParamId.CUBE_STATE)

    def poll(self, *, tolerate_loss: bool = False) -> ArmPoll:
        """ActPos, ActVel and CubeState of every module, pipelined."""
        params = self._STATUS_PARAMS
        on_bus = self.bus_modules
        requests = [GetParam(m, p) for m in on_bus for p in params]
        answers_of = dict(zip(on_bus, range(len(on_bus))))
        acks = (self.client.transact_partial(requests) if tolerate_loss
                else self.client.transact(requests))
        positions: list[float | None] = []
        velocities: list[float | None] = []
        states: dict[int, JointState | None] = {}
        for module in self.modules:
            if module in self._absent:
                positions.append(self.units.joint_user_deg(
                    module, self._absent_module_rad(module)))
                velocities.append(0.0)
                states[module] = ABSENT_STATE
                continue
            k = answers_of[module]
            answers = acks[len(params) * k:len(params) * (k + 1)]
            if any(a is None for a in answers):
                positions.append(None)
                velocities.append(None)
                states[module] = None
                continue
            pos, vel, state = (a.value for a in answers)
            positions.append(self.units.joint_user_deg(module, float(pos)))
            velocities.append(math.degrees(float(vel)))
            states[module] = joint_state(int(state))
        return ArmPoll(positions, velocities, states)

    def identity(self) -> ArmIdentity:
        """DefCubeSerial (0x1A) of every module, pipelined."""
        acks = self.transact([GetParam(m, ParamId.DEF_CUBE_SERIAL) for m in self.bus_modules],
                             idempotent=True)
        return ArmIdentity.of({m: int(a.value) for m, a in zip(self.bus_modules, acks)})

    def homed(self) -> bool:
        for attempt in range(self.HOMED_ATTEMPTS):
            try:
                acks = self.client.transact([GetParam(m, ParamId.CUBE_STATE)
                                             for m in self.bus_modules])
                break
            except ModuleTimeoutError:
                if attempt + 1 == self.HOMED_ATTEMPTS:
                    raise
        return all(StateFlag(a.value) & StateFlag.HOME_OK for a in acks)

    def session_mark(self) -> int | None:
        """The power-session mark every module carries (session_mark.py), None when one
        carries none or they differ; reads only."""
        from seqrun.drivers.powercube.session_mark import mark_of

        reads = [GetParam(m, p) for m in self.bus_modules
                 for p in (ParamId.FHOME_VEL, ParamId.DEF_HOME_VEL)]
        acks = self.transact(reads, idempotent=True)
        marks = {mark_of(float(acks[k].value), float(acks[k + 1].value))
                 for k in range(0, len(acks), 2)}
        return marks.pop() if len(marks) == 1 else None

    def write_session_mark(self, mark: int) -> bool:
        from seqrun.drivers.powercube.session_mark import marked_velocity

        stored = self.transact([GetParam(m, ParamId.DEF_HOME_VEL) for m in self.bus_modules],
                               idempotent=True)
        self.transact([SetParam(m, ParamId.FHOME_VEL, marked_velocity(float(a.value), mark))
                       for m, a in zip(self.bus_modules, stored)])
        return self.session_mark() == mark

    def watch_foreign(self, on_foreign: Callable[[ForeignTraffic], None]) -> None:
        from seqrun.drivers.powercube.foreign import ForeignFrameWatch

        self.client.add_frame_listener(ForeignFrameWatch(on_foreign,
                                                         echoes_own=self.echoes_own))

    def add_frame_listener(self, listener: Callable[[Any], None]) -> None:
        self.client.add_frame_listener(listener)

    def remove_frame_listener(self, listener: Callable[[Any], None]) -> None:
        self.client.remove_frame_listener(listener)

    # ------------------------------------------------------------------ limits
    _LIMIT_PARAMS = (ParamId.MIN_POS, ParamId.MAX_POS, ParamId.MAX_VEL, ParamId.MAX_ACC,
                     ParamId.MAX_CUR)

    def read_limits(self) -> list[JointLimits]:
        params, units = self._LIMIT_PARAMS, self.units
        on_bus = [j for j in self.arm.joints if j.present]
        stored = self.transact([GetParam(j.module, p) for j in on_bus for p in params],
                               idempotent=True)
        limits = []
        for joint in self.arm.joints:
            if not joint.present:   # no module: the arm file's values (nothing differs)
                limits.append(JointLimits(*joint.limits_deg, joint.max_velocity_deg_s,
                                          joint.max_acceleration_deg_s2, joint.max_current_a))
                continue
            k = on_bus.index(joint)
            low, high, velocity, acceleration, current = (
                float(a.value) for a in stored[len(params) * k:len(params) * (k + 1)])
            limits.append(JointLimits(units.joint_user_deg(joint.module, low),
                                      units.joint_user_deg(joint.module, high),
                                      math.degrees(velocity), math.degrees(acceleration),
                                      current))
        return limits

    def write_limits(self, values: Mapping[str, LimitValues]) -> int:
        writes: list[tuple[int, ParamId, float]] = []
        for joint in self.arm.joints:
            value = values.get(joint.name)
            if value is None or not joint.present:
                continue
            writes.append((joint.module, ParamId.MIN_POS,
                           self.units.joint_module_rad(joint.module, value.min_deg)))
            writes.append((joint.module, ParamId.MAX_POS,
                           self.units.joint_module_rad(joint.module, value.max_deg)))
            if value.max_velocity_deg_s is not None:
                writes.append((joint.module, ParamId.MAX_VEL,
                               math.radians(value.max_velocity_deg_s)))
            if value.max_acceleration_deg_s2 is not None:
                writes.append((joint.module, ParamId.MAX_ACC,
                               math.radians(value.max_acceleration_deg_s2)))
            if value.max_current_a is not None:
                writes.append((joint.module, ParamId.MAX_CUR, value.max_current_a))
        self.transact([SetParam(m, p, v) for m, p, v in writes])
        acks = self.transact([GetParam(m, p) for m, p, _ in writes], idempotent=True)
        for (module, param, wrote_rad), ack in zip(writes, acks):
            tolerance = (READBACK_TOLERANCE_A if param == ParamId.MAX_CUR
                         else READBACK_TOLERANCE_RAD)
            if abs(float(ack.value) - wrote_rad) > tolerance:
                joint = next(j for j in self.arm.joints if j.module == module)
                if param == ParamId.MAX_CUR:
                    read, wrote, unit = float(ack.value), wrote_rad, " A"
                elif param in (ParamId.MIN_POS, ParamId.MAX_POS):  # user coordinates, degrees
                    read, wrote, unit = (self.units.joint_user_deg(module, float(ack.value)),
                                         self.units.joint_user_deg(module, wrote_rad), "°")
                else:
                    read, wrote = math.degrees(float(ack.value)), math.degrees(wrote_rad)
                    unit = "°/s" if param == ParamId.MAX_VEL else "°/s²"
                raise RunAborted("limits_not_written",
                                 f"module {module} ({joint.name}): {param.name} reads back "
                                 f"{read:.3f}{unit}, wrote {wrote:.3f}{unit}", module=module)
        return len(writes)

    # ------------------------------------------------------------------ currents
    def read_currents(self, modules: Sequence[int]) -> dict[int, float]:
        """Cur (0x4D) of each module, in A: one GetParam each, in one exchange."""
        acks = self.transact([GetParam(m, ParamId.CUR) for m in modules], idempotent=True)
        return {m: float(ack.value) for m, ack in zip(modules, acks)}

    # ------------------------------------------------------------------ the gripper
    def _gripper(self):
        spec = self.arm.gripper
        if spec is None:
            raise RunAborted("no_gripper", "the arm file has no gripper")
        return spec

    def gripper_current_limit(self, current_a: float) -> float:
        from seqrun.drivers.powercube.gripper import CURRENT_TOLERANCE_A

        module = self._gripper().module
        self.transact([SetParam(module, ParamId.MAX_CUR, float(current_a))])
        [ack] = self.transact([GetParam(module, ParamId.MAX_CUR)], idempotent=True)
        read = float(ack.value)
        if abs(read - current_a) > CURRENT_TOLERANCE_A:
            raise RunAborted("limits_not_written", f"gripper (module {module}): MaxCur reads "
                             f"back {read:.3f} A, wrote {current_a:.3f} A", module=module)
        return read

    def gripper_move(self, width_mm: float, speed_mm_s: float) -> None:
        from seqrun.drivers.powercube.gripper import move_requests

        spec = self._gripper()
        acks = self.transact(move_requests(spec, width_mm, speed_mm_s))
        motion = acks[-1]
        if isinstance(motion, MotionExtAck) and motion.state.refuses_motion:
            state = self.read_state(spec.module)
            raise RunAborted("gripper_refused", f"gripper (module {spec.module}) refuses "
                             f"to move: {state.text}", module=spec.module)

    def gripper_read(self):
        from seqrun.drivers.powercube.gripper import read_requests, reading

        position, velocity, state = self.transact(read_requests(self._gripper()),
                                                  idempotent=True)
        return reading(float(position.value), float(velocity.value), int(state.value))

    # ------------------------------------------------------------------ watchdog
    def enable_watchdog(self, alive: Callable[[float], bool]) -> None:
        """Arm the modules' watchdogs (read-modify-write of Config) and keep them fed."""
        self._alive = alive  # a velocity motion arms the watchdog even when the file does not
        wd = self.arm.can.watchdog
        if not wd.enabled:
            return
        self._arm_watchdog(alive)

    def _arm_watchdog_for_velocity(self) -> None:
        """Before the first FVEL of a motion: the watchdog armed (once) and refreshed by
        every exchange from now on, whatever the arm file says, so that the joints stop
        within the modules' watchdog timeout when this process stops talking. Stays armed
        until :meth:`disable_watchdog` (a clean end) or the end of the session."""
        if self.client.watchdog_period is not None:
            return  # armed already (the arm file asks for it, or an earlier motion)
        self._velocity_watchdog = True
        alive = self._alive if self._alive is not None else (lambda within_s: False)
        self._arm_watchdog(alive)

    def _arm_watchdog(self, alive: Callable[[float], bool]) -> None:
        wd = self.arm.can.watchdog
        # Due at half the period: a refresh sent late (a loaded host, the GIL) still comes
        # within refresh_period_s of the last one, well inside the modules' timeout.
        self.client.watchdog_period = wd.refresh_period_s / 2
        configs = self.transact([GetParam(m, ParamId.CONFIG) for m in self.bus_modules],
                                idempotent=True)
        self.transact([SetParam(m, ParamId.CONFIG, int(a.value) | ConfigFlag.WATCHDOG_ENABLE)
                       for m, a in zip(self.bus_modules, configs)])
        self.client.refresh_watchdog()
        if not self.clock.is_virtual:
            self._keeper_stop.clear()
            self._keeper = threading.Thread(target=self._keep_watchdog, args=(alive,),
                                            daemon=True, name="seqrun-watchdog")
            self._keeper.start()
        self.emit("watchdog_enabled", refresh_period_s=wd.refresh_period_s)

    def _keep_watchdog(self, alive: Callable[[float], bool]) -> None:
        # Covers the times the run loop is not on the bus (between cycles, operator
        # prompts), but only while the loop shows signs of life: a loop that is stuck
        # (a deadlock, a hung call) must let the modules' watchdogs stop the arm.
        refresh = self.arm.can.watchdog.refresh_period_s
        while not self._keeper_stop.wait(refresh / 4):
            if not alive(refresh):
                continue
            try:
                self.client.service()
            except BusError:
                return

    def stop_watchdog_keeper(self) -> None:
        self._keeper_stop.set()

    def disable_watchdog(self) -> None:
        """After a clean end the arm keeps holding: clear WATCHDOG_ENABLE again."""
        if not self.arm.can.watchdog.enabled and not self._velocity_watchdog:
            return
        self._velocity_watchdog = False
        self._keeper_stop.set()
        try:
            configs = self.transact([GetParam(m, ParamId.CONFIG) for m in self.bus_modules],
                                    idempotent=True)
            self.transact([SetParam(m, ParamId.CONFIG,
                                    int(a.value) & ~int(ConfigFlag.WATCHDOG_ENABLE))
                           for m, a in zip(self.bus_modules, configs)])
            self.client.watchdog_period = None
            self.emit("watchdog_disabled")
        except BusError as exc:
            self.emit("watchdog_disable_failed", error=str(exc))

    @property
    def closed(self) -> bool:
        return self.client.closed

    def close(self) -> None:
        self._keeper_stop.set()
        self.client.close()
