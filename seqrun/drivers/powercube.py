"""The PowerCube driver: the executor's arm-driver calls over a :class:`PowerCubeClient`.

Everything that knows PowerCube frames lives here (or in the client and codec below it):

- reads: FPosStateDio per module, or ActPos + CubeState while that request is in
  quarantine after a lost acknowledge; a lost read is retried once by the other path;
- a control cycle: the setpoint law's requests (:mod:`seqrun.drivers.setpoints`) plus
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

import math
import threading
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from seqrun.arm import ArmDescription
from seqrun.drivers.base import (CommandConfirmation, EventSink, JointLimits, JointReading,
                                 JointState, LimitValues, MotionRefused)
from seqrun.drivers.setpoints import SetpointLaw, setpoint_law
from seqrun.errors import BusError, CodecError, ModuleTimeoutError, RunAborted
from seqrun.planner import Limits, MovePlan
from seqrun.powercube.codec import (BroadcastRequest, GetParam, GetParamAck, MotionExtAck,
                                    Request, SetMotion, SetParam)
from seqrun.powercube.protocol import CommandId, ConfigFlag, ParamId, ShortState, StateFlag

#: Rounds of "command, read back" before a module counts as not confirming.
DEFAULT_ATTEMPTS = 3

#: float32 on the wire: a read-back equal within this is the value written.
READBACK_TOLERANCE_RAD = 1e-6

#: Most specific first: the cause named in the report.
FAULT_CAUSES = ("TOW_ERROR", "BEYOND_HARD", "BEYOND_SOFT", "POWERFAULT", "COMM_ERROR",
                "CPU_OVERLOAD", "HALTED", "ERROR")


def _no_events(type_: str, **data: Any) -> None:
    """Event sink until the executor configures the driver."""


# ---------------------------------------------------------------------- state decoding
def short_state(flags: StateFlag) -> ShortState:
    """The short state a module would report for this state word (table B.3)."""
    short = ShortState(0)
    if flags & (StateFlag.ERROR | StateFlag.HALTED) or not flags & StateFlag.HOME_OK:
        short |= ShortState.NOT_OK
    if flags & StateFlag.MOTION:
        short |= ShortState.MOTION
    if flags & StateFlag.RAMP_END:
        short |= ShortState.RAMP_END
    return short


def joint_state(flags: StateFlag | int) -> JointState:
    """A module's state word, decoded."""
    flags = StateFlag(flags)
    faults = StateFlag(flags & StateFlag.FAULTS)
    cause = next((name.lower() for name in FAULT_CAUSES if faults & StateFlag[name]),
                 "not_homed")
    return JointState(homed=bool(flags & StateFlag.HOME_OK),
                      halted=bool(flags & StateFlag.HALTED),
                      moving=bool(flags & StateFlag.MOTION),
                      faulted=bool(faults), cause=cause, text=flags.describe(),
                      fault_text=faults.describe() if faults else "",
                      cycle_code=int(short_state(flags)))


# ---------------------------------------------------------------------- Halt / Reset, confirmed
def confirm_command(client, command: CommandId, modules: Iterable[int], *,
                    attempts: int = DEFAULT_ATTEMPTS, timeout: float | None = None,
                    retry_pause_s: float = 0.0) -> CommandConfirmation:
    """Broadcast Halt or Reset and confirm it on every module by reading its state back.

    1. Halt goes out **first** (``client.halt_now()``), before anything already queued on
       the bus is read: a flood of queued frames must not delay a stop. Reset goes out as
       its broadcast.
    2. Every module's CubeState is read back (pipelined); Halt is confirmed by HALTED,
       Reset by no fault bit left (a fault Reset cannot clear, e.g. a power fault, leaves
       the module unconfirmed, named with its state).
    3. For modules that did not confirm, the broadcast goes out again (after
       ``retry_pause_s``: time for a busy module to settle) and they are read again, up to
       ``attempts`` rounds in all.

    Never raises for the bus: a command that could not be sent gives ``sent=False`` and
    the error; modules that never answer are unconfirmed with "no answer".
    """
    if command not in (CommandId.HALT, CommandId.RESET):
        raise CodecError(f"confirm_command: {command.name} is not Halt or Reset")
    name = command.name.lower()
    wanted = tuple(dict.fromkeys(modules))
    result = CommandConfirmation(name, wanted, unconfirmed={m: "no answer" for m in wanted})
    clock = client.clock
    t_first: float | None = None
    for attempt in range(1, max(1, attempts) + 1):
        result.attempts = attempt
        if attempt > 1 and retry_pause_s > 0:
            client.idle(retry_pause_s)
        try:
            if command == CommandId.HALT:
                client.halt_now()
            else:
                client.transact([BroadcastRequest(command, 0)])
            result.sent = True
            if t_first is None:
                t_first = clock.now()
        except Exception as exc:  # noqa: BLE001 - any failure of the bus is reported
            result.error = f"sending the {command.name.capitalize()} failed: {exc}"
            break
        waiting = [m for m in wanted if m in result.unconfirmed]
        try:
            acks = client.transact_partial([GetParam(m, ParamId.CUBE_STATE) for m in waiting],
                                           timeout)
        except Exception as exc:  # noqa: BLE001
            result.error = f"reading the modules back failed: {exc}"
            continue
        for module, ack in zip(waiting, acks):
            if not isinstance(ack, GetParamAck):
                result.unconfirmed[module] = "no answer"
                continue
            state = joint_state(int(ack.value))  # type: ignore[arg-type]
            result.states[module] = state
            took_effect = state.halted if command == CommandId.HALT else not state.faulted
            if took_effect:
                result.unconfirmed.pop(module, None)
            else:
                result.unconfirmed[module] = f"state {state.text}"
        if not result.unconfirmed:
            result.error = None
            break
    result.duration_s = 0.0 if t_first is None else clock.now() - t_first
    return result


# ---------------------------------------------------------------------- the driver
class _NotOkAcknowledge(Exception):
    """An acknowledge said NOT_OK (raised from inside the exchange to end it at once)."""

    def __init__(self, module: int, state: ShortState) -> None:
        super().__init__(f"module {module}: NOT_OK")
        self.module = module
        self.state = state


_FPOS_STATE_DIO, _CUBE_STATE = ParamId.FPOS_STATE_DIO, ParamId.CUBE_STATE
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

    def __init__(self, client, arm: ArmDescription) -> None:
        self.client = client
        self.arm = arm
        self.clock = client.clock
        self.modules: list[int] = arm.module_ids
        self.emit: EventSink = _no_events
        self.cycle_s = 1.0 / arm.control.cycle_hz
        self.run_limits = Limits.from_arm(arm)
        self.command_mode = arm.control.command_mode
        self._run_law: SetpointLaw | None = None
        self._law: SetpointLaw | None = None
        self._keeper: threading.Thread | None = None
        self._keeper_stop = threading.Event()

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
        primary = GetParam(module, ParamId.FPOS_STATE_DIO)
        if not self.client.is_tainted(primary):
            return [primary]
        return [GetParam(module, ParamId.ACT_POS), GetParam(module, ParamId.CUBE_STATE)]

    # ------------------------------------------------------------------ reading
    def read(self) -> JointReading:
        """Read position and short state of every module (pipelined, lost reads retried)."""
        return self._cycle([], [])

    def read_state(self, module: int) -> JointState:
        return joint_state(self.client.read_state(module))

    def read_states(self, modules: Sequence[int] | None = None) -> dict[int, JointState]:
        """CubeState of several modules, pipelined."""
        modules = self.modules if modules is None else list(modules)
        acks = self.transact([GetParam(m, ParamId.CUBE_STATE) for m in modules], idempotent=True)
        return {m: joint_state(a.value) for m, a in zip(modules, acks)}

    # ------------------------------------------------------------------ motion
    def start_motion(self, moving: list[int], limits: Limits, *,
                     command_mode: str | None = None) -> None:
        law = self._run_law
        if law is None:
            raise RuntimeError("PowerCubeDriver.configure() was not called")
        if command_mode is not None and command_mode != self.command_mode:
            law = setpoint_law(command_mode, self.arm, self.cycle_s, self.run_limits)
        self._law = law
        start = law.start(moving, limits)
        if start:
            self.transact(start)

    def cycle(self, plan: MovePlan, t: float, moving: list[int],
              measured_deg: np.ndarray) -> JointReading:
        law = self._law
        if law is None:
            raise RuntimeError("PowerCubeDriver.start_motion() was not called")
        return self._cycle(law.cycle(plan, t, moving, measured_deg), moving, halt_early=True)

    def end_motion(self) -> None:
        self._law = self._run_law

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
        reads = [r for m in self.modules if m not in moving_modules for r in self._reads(m)]
        batch = requests + reads
        try:
            acks = self.client.transact_partial(
                batch, on_ack=_raise_on_not_ok if halt_early else None)
        except _NotOkAcknowledge as bad:
            raise MotionRefused(bad.module, bad.state) from None
        times = list(getattr(self.client, "last_ack_times", ()))
        lost = [i for i, (r, a) in enumerate(zip(batch, acks)) if a is None and _acked(r)]
        if any(not isinstance(batch[i], GetParam) for i in lost):
            bad = next(batch[i] for i in lost if not isinstance(batch[i], GetParam))
            raise ModuleTimeoutError(bad.module, _describe_request(bad),
                                     self.client.response_timeout)
        if lost:
            modules = list(dict.fromkeys(batch[i].module for i in lost))
            retry = [r for m in modules for r in self._reads(m)]
            # The retry must go out at once: a request still in quarantine would first
            # wait it out (up to 4 response timeouts) while the joints move unwatched. Both
            # read paths of a module lost within one quarantine is a fault.
            blocked = next((r for r in retry if self.client.is_tainted(r)), None)
            if blocked is not None:
                bad = next(batch[i] for i in lost if batch[i].module == blocked.module)
                lost_ack = ModuleTimeoutError(bad.module, _describe_request(bad),
                                              self.client.response_timeout)
                raise RunAborted("no_acknowledge", f"{lost_ack}; not retried: its other read "
                                 "path is still in quarantine after an earlier lost "
                                 "acknowledge", module=bad.module)
            self.emit("retry", modules=modules, what="read")
            batch, acks = batch + retry, acks + self.transact(retry)
            times += list(getattr(self.client, "last_ack_times", ()))
        positions: dict[int, float] = {}
        states: dict[int, ShortState] = {}
        # when each position was answered (the modules measure as they answer)
        answered: dict[int, float | None] = {}
        for ack, at in zip(acks, times + [None] * (len(acks) - len(times))):
            if isinstance(ack, MotionExtAck):
                positions[ack.module], states[ack.module] = ack.position, ack.state
                answered[ack.module] = at
            elif isinstance(ack, GetParamAck):
                if ack.param == ParamId.FPOS_STATE_DIO:
                    positions[ack.module] = ack.value.position
                    states[ack.module] = ack.value.state
                    answered[ack.module] = at
                elif ack.param == ParamId.ACT_POS:
                    positions[ack.module] = float(ack.value)
                    answered[ack.module] = at
                elif ack.param == ParamId.CUBE_STATE:
                    states[ack.module] = short_state(StateFlag(ack.value))
        module_rad = np.array([positions[m] for m in self.modules])
        stamps = [answered.get(m) for m in self.modules]
        at = None if None in stamps else np.array(stamps, dtype=float)
        return JointReading(module_rad, states, at)  # type: ignore[arg-type]

    # ------------------------------------------------------------------ commands
    def reset(self, modules: Sequence[int] | None) -> None:
        self._command(self.client.reset, modules)

    def home(self, modules: Sequence[int] | None) -> None:
        self._command(self.client.home, modules)

    def halt(self, modules: Sequence[int] | None) -> None:
        self._command(self.client.halt, modules)

    @staticmethod
    def _command(send: Callable[[int | None], None], modules: Sequence[int] | None) -> None:
        if modules is None:
            send(None)          # one broadcast
        else:
            for module in modules:
                send(module)

    def halt_and_confirm(self) -> CommandConfirmation:
        return confirm_command(self.client, CommandId.HALT, self.modules)

    # ------------------------------------------------------------------ limits
    _LIMIT_PARAMS = (ParamId.MIN_POS, ParamId.MAX_POS, ParamId.MAX_VEL, ParamId.MAX_ACC)

    def read_limits(self) -> list[JointLimits]:
        params = self._LIMIT_PARAMS
        stored = self.transact([GetParam(j.module, p) for j in self.arm.joints for p in params],
                               idempotent=True)
        return [JointLimits(*(float(a.value) for a in stored[k:k + len(params)]))
                for k in range(0, len(stored), len(params))]

    def write_limits(self, values: Mapping[str, LimitValues]) -> int:
        writes: list[tuple[int, ParamId, float]] = []
        for joint in self.arm.joints:
            value = values.get(joint.name)
            if value is None:
                continue
            writes.append((joint.module, ParamId.MIN_POS, joint.to_module_rad(value.min_deg)))
            writes.append((joint.module, ParamId.MAX_POS, joint.to_module_rad(value.max_deg)))
            if value.max_velocity_deg_s is not None:
                writes.append((joint.module, ParamId.MAX_VEL,
                               math.radians(value.max_velocity_deg_s)))
            if value.max_acceleration_deg_s2 is not None:
                writes.append((joint.module, ParamId.MAX_ACC,
                               math.radians(value.max_acceleration_deg_s2)))
        self.transact([SetParam(m, p, v) for m, p, v in writes])
        acks = self.transact([GetParam(m, p) for m, p, _ in writes], idempotent=True)
        for (module, param, value), ack in zip(writes, acks):
            if abs(float(ack.value) - value) > READBACK_TOLERANCE_RAD:
                joint = next(j for j in self.arm.joints if j.module == module)
                if param in (ParamId.MIN_POS, ParamId.MAX_POS):  # user coordinates, degrees
                    read, wrote, unit = (joint.to_user_deg(float(ack.value)),
                                         joint.to_user_deg(value), "°")
                else:
                    read, wrote = math.degrees(float(ack.value)), math.degrees(value)
                    unit = "°/s" if param == ParamId.MAX_VEL else "°/s²"
                raise RunAborted("limits_not_written",
                                 f"module {module} ({joint.name}): {param.name} reads back "
                                 f"{read:.3f}{unit}, wrote {wrote:.3f}{unit}", module=module)
        return len(writes)

    # ------------------------------------------------------------------ watchdog
    def enable_watchdog(self, alive: Callable[[float], bool]) -> None:
        """Arm the modules' watchdogs (read-modify-write of Config) and keep them fed."""
        wd = self.arm.can.watchdog
        if not wd.enabled:
            return
        # Due at half the period: a refresh sent late (a loaded host, the GIL) still comes
        # within refresh_period_s of the last one, well inside the modules' timeout.
        self.client.watchdog_period = wd.refresh_period_s / 2
        configs = self.transact([GetParam(m, ParamId.CONFIG) for m in self.modules],
                                idempotent=True)
        self.transact([SetParam(m, ParamId.CONFIG, int(a.value) | ConfigFlag.WATCHDOG_ENABLE)
                       for m, a in zip(self.modules, configs)])
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
        if not self.arm.can.watchdog.enabled:
            return
        self._keeper_stop.set()
        try:
            configs = self.transact([GetParam(m, ParamId.CONFIG) for m in self.modules],
                                    idempotent=True)
            self.transact([SetParam(m, ParamId.CONFIG,
                                    int(a.value) & ~int(ConfigFlag.WATCHDOG_ENABLE))
                           for m, a in zip(self.modules, configs)])
            self.client.watchdog_period = None
            self.emit("watchdog_disabled")
        except BusError as exc:
            self.emit("watchdog_disable_failed", error=str(exc))

    def close(self) -> None:
        self._keeper_stop.set()
        self.client.close()
