"""One simulated Schunk PRL (PowerCube) module: parameters, state word and motion.

:class:`SimModule` answers decoded PowerCube requests (:mod:`seqrun.powercube.codec`) the
way ``shared/reference/powercube-protocol.md`` says a module does, and moves its joint
deterministically on a :class:`~seqrun.clock.Clock`. It has no thread: whenever it is
touched it catches up to the requested time. Motion is piecewise constant acceleration,
evaluated in closed form, so a ramp ends exactly at its target at exactly the planned time;
events (end of a ramp or step, soft-limit crossing, watchdog expiry) are found exactly too,
so the result never depends on how often the module was looked at.

Behaviour (sources in the reference; **[I]** marks an assumption that is an option of
:class:`ModuleOptions`):

- Power-on: encoders at the given position (0 for an arm homed at Park), limits the
  module's stored ones (:func:`default_parameters`), HOME_OK clear and the brake engaged
  until Home [I: thesis 5.1; PRL drivers elsewhere saw HOME_OK at boot —
  ``home_ok_at_power_on``]. Home sets HOME_OK without moving (a PRL has absolute
  encoders). [I: ``homing_travel``, for modules with incremental encoders: Home clears
  HOME_OK and travels to the home switch (``home_switch_position``, module rad) at
  |FHomeVel| with DefHomeAcc, MOTION set and motion commands refused on the way; on the
  switch HOME_OK and SWR are set. Halt or Reset on the way leave it not homed.]
- Motion (SetMotion) is refused before Home, while ERROR/HALTED or any other fault bit is
  set, for current and loop modes (not simulated), and when it would take a module that is
  at or beyond a soft limit further out. A refused command is still acknowledged and its
  extended ack has NOT_OK [I: ``ack_refused_motion``].
- FRAMP: a trapezoid re-planned from the current position *and* velocity, bounded by
  min(TargetVel, MaxVel) and min(TargetAcc, MaxAcc), target clamped into [MinPos, MaxPos].
  FSTEP: straight line to the (clamped) position in the given ms, INPROGRESS while
  running; a step that arrives while one runs waits (FULLBUFFER) and a newer one replaces
  the waiting one [I: ``step_buffering``]; a step is never faster than MaxVel (it takes
  longer instead) [I]. FVEL: changes velocity at min(TargetAcc, MaxAcc)
  [I: ``velocity_mode_acceleration``], clamped to MaxVel, and runs until a soft limit.
- Crossing a soft limit outward: the module stops exactly at the limit with BEYOND_SOFT
  plus ``soft_limit_flags`` [I: ERROR|HALTED]. A module that is outside its limits (for
  example after MinPos was written above its position) has no fault because of that; it
  accepts motion back towards its range only.
- Halt: stops at once (velocity 0), HALTED, refuses motion until Reset. Reset clears
  ERROR, HALTED, TOW_ERROR, COMM_ERROR, BEYOND_SOFT and CURLIMIT, and stops [I] any motion;
  HOME_OK stays [I].
- SYNC_MOTION in Config: a motion command is stored and starts at the StartMove broadcast
  (0x0F); the newest stored command wins [I]. Without the bit 0x0F does nothing.
- Watchdog: with WATCHDOG_ENABLE in Config the first refresh (broadcast or addressed 0x07)
  arms it; ``watchdog_timeout`` [I: 50 ms] after the last refresh the module stops with
  ``watchdog_flags`` [I: HALTED|ERROR|COMM_ERROR] and is disarmed until the next refresh.
  [I: ``addressed_refresh_arms_watchdog``, the KTH driver's view: only an addressed
  refresh arms it, setting WATCHDOG_ENABLE itself; broadcasts keep an armed one alive.]
- Parameters: every id of :class:`~seqrun.powercube.protocol.ParamId` answers GetExtended
  with its wire type. Writing a read-only one (DEF_*, ActPos, TargetPos, CubeState, ...) is
  acknowledged and ignored [I] — e.g. TargetPos, which the thesis believed writable.
  Integer twins (IMinPos, TargetVelInc, IPos, ...) convert with IncRatio (rad per tick).
- Extended acks report the position and short state at receipt (before the command acts).
- Written parameters live in the module's RAM: a power-on (a new module, e.g. at ``sim
  serve`` restart) starts again from the stored ones (:func:`default_parameters`, the
  ``DEF_*`` values). [I: ``fhome_vel_saved_on_write``, a firmware that saves FHomeVel to
  its EEPROM as it is written: DefHomeVel then reads the written value too.]
- Config DISABLE_ACK suppresses every acknowledge [I, from the bit's name only].

- Current limit: a motion needs a current (a made-up, deterministic motor model: a fraction
  of the module's rated DefMaxCur per rad/s^2 and per rad/s, :func:`required_current`);
  Cur reads it, at most MaxCur. A motion whose ramp needs more than MaxCur sets CURLIMIT
  and runs with its acceleration and speed scaled down until it needs MaxCur (steps take
  longer): the joint lags its host's plan, whose following-error monitor halts it [I:
  ``current_limit_halts``: the module stops at once with CURLIMIT|ERROR instead].

Not simulated: current control, following-error monitoring (TOW_ERROR only as an injected fault),
brake timing, hard limits, temperatures and supply voltages (constants),
parameter persistence (SaveParams is acknowledged), the state frame 0x060+id, the
Internal (0x04) and SetIStep (0x0D) commands (the codec does not decode them).
"""

from __future__ import annotations

import math
import struct
from collections.abc import Mapping
from dataclasses import dataclass, field

from seqrun.clock import Clock
from seqrun.powercube.codec import (
    Ack,
    BroadcastRequest,
    CommandAck,
    CommandRequest,
    GetParam,
    GetParamAck,
    MotionAck,
    MotionExtAck,
    PosStateDio,
    Request,
    SetMotion,
    SetParam,
    SetParamAck,
)
from seqrun.powercube.protocol import (
    PARAM_TYPES,
    CommandId,
    ConfigFlag,
    MotionMode,
    ParamId,
    SetupFlag,
    ShortState,
    StateFlag,
    WireType,
)

#: Joint limits a PRL module of this arm has stored at power-on (rad): narrower than the
#: user limits, the thesis saw joint 1 stop at about -120 deg when told to go to -180.
DEFAULT_POSITION_LIMIT = 2.0944
#: DefCubeVersion; the ROS driver uses FSTEP on PRL modules from version 4638.
DEFAULT_CUBE_VERSION = 0x4638

_F = StateFlag
#: Cleared by Reset (reference D.2).
RESETTABLE = (_F.ERROR | _F.HALTED | _F.TOW_ERROR | _F.COMM_ERROR | _F.BEYOND_SOFT
              | _F.CURLIMIT)
_MOTION_BITS = (_F.MOTION | _F.RAMP_ACC | _F.RAMP_STEADY | _F.RAMP_DEC | _F.RAMP_END
                | _F.INPROGRESS | _F.FULLBUFFER)
_NO_FLAGS = StateFlag(0)
_RAMP_ACC_FLAG, _RAMP_STEADY_FLAG, _RAMP_DEC_FLAG = _F.RAMP_ACC, _F.RAMP_STEADY, _F.RAMP_DEC
_MOTION_MASK = int(_MOTION_BITS)
_MOTION, _RAMP_END = int(_F.MOTION), int(_F.RAMP_END)
_INPROGRESS, _FULLBUFFER = int(_F.INPROGRESS), int(_F.FULLBUFFER)
_ERROR_OR_HALTED, _HOME_OK = int(_F.ERROR | _F.HALTED), int(_F.HOME_OK)
_SWR = int(_F.SWR)
_SHORT_STATES = [ShortState(i) for i in range(256)]
_FAULTS, _NOT_OK = int(StateFlag.FAULTS), int(ShortState.NOT_OK)
_DISABLE_ACK, _WATCHDOG_ENABLE = int(ConfigFlag.DISABLE_ACK), int(ConfigFlag.WATCHDOG_ENABLE)
_SYNC_MOTION = int(ConfigFlag.SYNC_MOTION)
#: Position tolerance (rad) below which a limit counts as reached, not crossed; targets are
#: clamped exactly onto limits, so rounding must not turn "stopped at MinPos" into a fault.
_LIMIT_EPS = 1e-9
#: How far (rad) inside its limits a whole motion profile must stay for the soft-limit
#: search to be skipped: a million times the rounding of a position of a few radians.
_CLEAR = 1e-9


@dataclass(frozen=True)
class ModuleOptions:
    """The behaviours no source confirms ([I] in the reference), each one switchable."""

    #: HOME_OK at power-on. False: motion is refused until Home (thesis 5.1, this arm).
    home_ok_at_power_on: bool = False
    #: Refused motion commands are still acknowledged (extended acks show NOT_OK).
    ack_refused_motion: bool = True
    #: Command acks are ``[cmd, 0x64]`` (DLC 2); False sends ``[cmd]`` only.
    command_ack_trailer: bool = True
    #: An addressed WatchdogRefresh ``0x0E0+m : [07]`` is acknowledged like other commands.
    ack_addressed_watchdog: bool = True
    #: True: the first *addressed* WatchdogRefresh arms the watchdog (and sets
    #: WATCHDOG_ENABLE in Config), whatever Config said; broadcast refreshes only keep an
    #: armed watchdog alive (KTH driver). False: WATCHDOG_ENABLE in Config, and any refresh
    #: arms it.
    addressed_refresh_arms_watchdog: bool = False
    #: Seconds without refresh before an armed watchdog stops the module.
    watchdog_timeout: float = 0.050
    #: State set when the watchdog expires.
    watchdog_flags: StateFlag = _F.HALTED | _F.ERROR | _F.COMM_ERROR
    #: State set (besides BEYOND_SOFT) when the joint crosses a soft limit.
    soft_limit_flags: StateFlag = _F.ERROR | _F.HALTED
    #: FVEL changes velocity at min(TargetAcc, MaxAcc); False jumps to the new velocity.
    velocity_mode_acceleration: bool = True
    #: FSTEP while a step runs waits for it (FULLBUFFER); False replaces it at once.
    step_buffering: bool = True
    #: Config DISABLE_ACK suppresses acknowledges.
    honour_disable_ack: bool = True
    #: A module drops (ignores, does not answer) an addressed request that arrives while
    #: it is still busy with the previous one, i.e. before its acknowledge of that one has
    #: been sent on the wire. Off: requests queue up. No driver sends a second request
    #: before the answer, so real firmware was never seen doing either; on, it catches a
    #: host that does. Broadcasts (Halt, watchdog, ...) are always taken.
    drop_request_while_busy: bool = False
    #: FRAMP does not blend: every FRAMP re-plans its trapezoid from standstill (v = 0) at
    #: the current position instead of from the current velocity. No published driver
    #: streams FRAMP, so real firmware behaviour is unconfirmed [I].
    framp_from_standstill: bool = False
    #: Home travels to the home switch before HOME_OK (modules with incremental
    #: encoders); False: HOME_OK at once, no travel (a PRL: absolute encoders, thesis 5.1).
    homing_travel: bool = False
    #: Where the home switch is (module coordinates, rad) with ``homing_travel``.
    home_switch_position: float = 0.0
    #: A motion needing more current than MaxCur stops the module at once with
    #: CURLIMIT|ERROR; False: it runs slower (the current clamped), the joint lags.
    current_limit_halts: bool = False
    #: Serial numbers (DefCubeSerial, 0x1A): module M says ``serial_base + M``. 0: every
    #: simulated arm draws a base of its own (two ``seqrun sim serve`` are two arms, as
    #: the zero reference, keyed by the serials, must see them).
    serial_base: int = 0
    #: The simulated arm also carries a PowerCube gripper (PG 70 model,
    #: :mod:`seqrun.sim.gripper`) at this module id; 0: none.
    gripper_module: int = 0
    #: Width (mm) of the part standing between the gripper's jaws; 0: no part (a grip
    #: closes fully).
    gripper_part_mm: float = 0.0
    #: SetExtended FHomeVel (0x64) is also saved as the stored DefHomeVel (0x0F), as if
    #: the firmware kept it over a power cycle. False: it lives in RAM only, and a
    #: power-on starts from DefHomeVel. No source says which [I].
    fhome_vel_saved_on_write: bool = False


#: Environment variable the command line reads simulator options from, e.g.
#: ``SEQRUN_SIM_OPTIONS="framp_from_standstill drop_request_while_busy"``.
SIM_OPTIONS_ENV = "SEQRUN_SIM_OPTIONS"


#: The motor model of the current limit: current needed per rad/s^2 and per rad/s, as a
#: fraction of the module's rated current (DefMaxCur) at DefMaxAcc and at DefMaxVel. With
#: it the arm file's limits (30 deg/s, 60 deg/s^2) need under 0.8 A on every module: the
#: thesis' 2 A limit never binds; 0.5 A on joint 1 does.
CURRENT_PER_ACCELERATION, CURRENT_PER_VELOCITY = 0.1, 0.05


#: The serial base of a module made on its own (no arm around it to choose one).
DEFAULT_SERIAL_BASE = 41000


def default_parameters(module_id: int) -> dict[ParamId, float | int]:
    """Stored parameters of a PRL module of this arm at power-on (all values [I] unless
    the reference gives them: version 0x4638, 1 Mbit/s, PRL setup bits, address)."""
    max_cur = {1: 12.0, 2: 12.0, 3: 8.0, 4: 8.0, 5: 4.0, 6: 4.0, 7: 2.5}.get(module_id, 4.0)
    pulses_per_turn, gear_ratio = 4096, 101.0
    values: dict[ParamId, float | int] = {
        ParamId.DEF_GEAR_RATIO: gear_ratio,
        ParamId.DEF_MIN_POS: -DEFAULT_POSITION_LIMIT,
        ParamId.DEF_MAX_POS: DEFAULT_POSITION_LIMIT,
        ParamId.DEF_MAX_DELTA_POS: 0.1,
        ParamId.DEF_MAX_DELTA_VEL: 0.5,
        ParamId.DEF_CUR_RATIO: 1.0,
        ParamId.DEF_MAX_VEL: 2.0,  # rad/s, the URDF's velocity limit for every LWA joint
        ParamId.DEF_MAX_ACC: 2.0,
        ParamId.DEF_MAX_CUR: max_cur,
        ParamId.DEF_HOME_VEL: 0.1,
        ParamId.DEF_HOME_ACC: 0.5,
        ParamId.DEF_CUBE_SERIAL: DEFAULT_SERIAL_BASE + module_id,
        ParamId.DEF_CONFIG: int(ConfigFlag.BRAKE_PRESENT | ConfigFlag.BRAKE_AT_POWERON),
        ParamId.DEF_PULSES_PER_TURN: pulses_per_turn,
        ParamId.DEF_CUBE_VERSION: DEFAULT_CUBE_VERSION,
        ParamId.DEF_BRAKE_TIMEOUT: 500,
        ParamId.DEF_ADDRESS: module_id,
        ParamId.DEF_PRIM_BAUD: 3,  # 1000 kbit/s
        ParamId.DEF_SCND_BAUD: 3,
        ParamId.DEF_C0: 20, ParamId.DEF_DAMP: 4, ParamId.DEF_A0: 3,
        ParamId.DEF_BURN_COUNT: 1,
        ParamId.SETUP: int(SetupFlag.ABSOLUTE | SetupFlag.CAN),
        ParamId.INC_RATIO: 2 * math.pi / (pulses_per_turn * gear_ratio),  # rad per tick
        ParamId.MAX_DELTA_POS: 0.1,
        ParamId.MIN_POS: -DEFAULT_POSITION_LIMIT,
        ParamId.MAX_POS: DEFAULT_POSITION_LIMIT,
        ParamId.MAX_VEL: 2.0,
        ParamId.MAX_ACC: 2.0,
        ParamId.MAX_CUR: max_cur,
        # Without a TargetVel the thesis calls a FRAMP "not safe", i.e. it moves fast.
        ParamId.TARGET_VEL: 2.0,
        ParamId.TARGET_ACC: 2.0,
        ParamId.ACT_C0: 20, ParamId.ACT_DAMP: 4, ParamId.ACT_A0: 3,
        ParamId.FHOME_VEL: 0.1,
        ParamId.MIN_LOGIC: 18.0, ParamId.MAX_LOGIC: 30.0,
        ParamId.MIN_MOTOR: 18.0, ParamId.MAX_MOTOR: 30.0,
        ParamId.NOM_CUR: max_cur / 2, ParamId.HMAX_CUR: max_cur,
        ParamId.CURRENT_LIMIT: max_cur,
        ParamId.MOT_SUPPLY: 24.0, ParamId.LOGIC_SUPPLY: 24.0, ParamId.TEMP: 30.0,
    }
    values[ParamId.CONFIG] = values[ParamId.DEF_CONFIG]
    return values


#: Parameters SetExtended changes (R/W in the reference); writes to any other are
#: acknowledged and ignored.
WRITABLE_PARAMS: frozenset[ParamId] = frozenset({
    ParamId.DEF_PRIM_BAUD, ParamId.DEF_SCND_BAUD, ParamId.DIO_SETUP, ParamId.TARGET_POS_INC,
    ParamId.TARGET_VEL_INC, ParamId.TARGET_ACC_INC, ParamId.HOME_OFFSET_INC, ParamId.CONFIG,
    ParamId.INC_RATIO, ParamId.MAX_DELTA_POS, ParamId.MIN_POS, ParamId.MAX_POS,
    ParamId.MAX_VEL, ParamId.MAX_ACC, ParamId.MAX_CUR, ParamId.TARGET_VEL, ParamId.TARGET_ACC,
    ParamId.ACT_C0, ParamId.ACT_DAMP, ParamId.ACT_A0, ParamId.HOME_OFFSET,
    ParamId.IMAX_DELTA_POS, ParamId.IMIN_POS, ParamId.IMAX_POS, ParamId.IMAX_VEL,
    ParamId.IMAX_ACC, ParamId.FHOME_VEL, ParamId.IHOME_VEL, ParamId.SYNC_TIME,
    ParamId.LOAD_LIMIT, ParamId.MAX_LOAD_GRADIENT, ParamId.LOAD_DELTA_TIME,
    ParamId.MIN_LOGIC, ParamId.MAX_LOGIC, ParamId.MIN_MOTOR, ParamId.MAX_MOTOR,
    ParamId.NOM_CUR, ParamId.HMAX_CUR, ParamId.LOGIC_UNDERSHOOT_TIME,
    ParamId.LOGIC_OVERSHOOT_TIME, ParamId.MOTOR_UNDERSHOOT_TIME,
    ParamId.MOTOR_OVERSHOOT_TIME, ParamId.NOM_CUR_OVERSHOOT_TIME,
    ParamId.HMAX_CUR_OVERSHOOT_TIME, ParamId.KP_PWM_LIMIT, ParamId.CURRENT_LIMIT,
})

#: Integer (tick) parameters that are views of a float one: value_ticks = value / IncRatio.
_TICK_TWINS: dict[ParamId, ParamId] = {
    ParamId.TARGET_POS_INC: ParamId.TARGET_POS, ParamId.TARGET_VEL_INC: ParamId.TARGET_VEL,
    ParamId.TARGET_ACC_INC: ParamId.TARGET_ACC, ParamId.IMAX_DELTA_POS: ParamId.MAX_DELTA_POS,
    ParamId.IMIN_POS: ParamId.MIN_POS, ParamId.IMAX_POS: ParamId.MAX_POS,
    ParamId.IMAX_VEL: ParamId.MAX_VEL, ParamId.IMAX_ACC: ParamId.MAX_ACC,
    ParamId.IHOME_VEL: ParamId.FHOME_VEL, ParamId.IPOS: ParamId.ACT_POS,
    ParamId.POS_COUNT: ParamId.ACT_POS, ParamId.IVEL: ParamId.ACT_VEL,
    ParamId.IDELTA_POS: ParamId.DELTA_POS,
}

#: Event kinds of SimModule._next_event.
_WATCHDOG, _PROFILE_END, _SOFT_LIMIT = "watchdog", "profile end", "soft limit"

#: mode -> (its plain twin, the twin's is_float, is_extended_ack, is_float): properties
#: looked up once.
_MODE_FACTS = {m: (m.without_ext_ack(), m.without_ext_ack().is_float, m.is_extended_ack,
                   m.is_float) for m in MotionMode}
_RAMP_MODES = {MotionMode.FRAMP, MotionMode.IRAMP}
_STEP_MODES = {MotionMode.FSTEP, MotionMode.ISTEP}
_VELOCITY_MODES = {MotionMode.FVEL, MotionMode.IVEL}
_SIMULATED_MODES = frozenset(_RAMP_MODES | _STEP_MODES | _VELOCITY_MODES)
_RAMP_OR_VELOCITY_MODES = frozenset(_RAMP_MODES | _VELOCITY_MODES)


# --------------------------------------------------------------------------------------
# Motion profiles: piecewise constant acceleration from a start state


@dataclass
class _Segment:
    t_start: float  # seconds after the profile start
    duration: float  # may be inf (velocity mode cruise)
    p: float
    v: float
    a: float
    phase: StateFlag  # RAMP_ACC / RAMP_STEADY / RAMP_DEC, or 0 for steps


@dataclass
class _Profile:
    """A motion from ``(p0, v0)`` at ``t0``; ``target`` is where it ends exactly (None for
    velocity mode, which runs until a soft limit or a new command)."""

    kind: str  # "ramp" | "step" | "velocity" | "home" (travel to the home switch)
    t0: float
    segments: list[_Segment]
    target: float | None
    end: float = field(init=False)
    #: (t, sample(t)) of the last call: a motion command samples the profile at the same
    #: instant several times (position and state at receipt, refusal check, re-plan).
    _last_sample: tuple | None = field(default=None, init=False, repr=False, compare=False)
    #: Lowest and highest position of the whole profile, once asked (see span()).
    _span: tuple | None = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        last = self.segments[-1]
        self.end = self.t0 + last.t_start + last.duration

    def sample(self, t: float) -> tuple[float, float, _Segment]:
        """Position and velocity at ``t`` (t0 <= t <= end)."""
        last = self._last_sample
        if last is not None and last[0] == t:
            return last[1]
        tau = t - self.t0
        segment = self.segments[0]
        for candidate in self.segments:
            if candidate.t_start <= tau:
                segment = candidate
            else:
                break
        d = min(max(tau - segment.t_start, 0.0), segment.duration)
        if self.target is not None and t >= self.end:
            result = self.target, 0.0, segment
        else:
            position = segment.p + segment.v * d + 0.5 * segment.a * d * d
            result = position, segment.v + segment.a * d, segment
        self._last_sample = (t, result)
        return result

    def span(self) -> tuple[float, float] | None:
        """(lowest, highest) position anywhere on the profile, from its segments' ends and
        turning points; None when it has no bound (a velocity-mode cruise)."""
        span = self._span
        if span is None:
            positions = []
            for segment in self.segments:
                duration, p, v, a = segment.duration, segment.p, segment.v, segment.a
                if not math.isfinite(duration):
                    if v != 0 or a != 0:
                        self._span = (None,)
                        return None
                    duration = 0.0
                positions.append(p)
                positions.append(p + v * duration + 0.5 * a * duration * duration)
                if a != 0 and 0.0 < -v / a < duration:
                    turn = -v / a
                    positions.append(p + v * turn + 0.5 * a * turn * turn)
            if self.target is not None:
                positions.append(self.target)
            span = self._span = (min(positions), max(positions))
        return None if span[0] is None else span


def _build_profile(kind: str, t0: float, p0: float, v0: float,
                   pieces: list[tuple[float, float]], target: float | None) -> _Profile:
    segments = []
    tau, p, v = 0.0, p0, v0
    for duration, a in pieces:
        if kind == "step":
            phase = _NO_FLAGS
        elif a == 0:
            phase = _RAMP_STEADY_FLAG
        else:
            # Accelerating if |v| grows over the segment (judged at its middle).
            middle = v + a * (duration / 2 if math.isfinite(duration) else 1.0)
            phase = _RAMP_ACC_FLAG if a * middle > 0 else _RAMP_DEC_FLAG
        segments.append(_Segment(tau, duration, p, v, a, phase))
        if math.isfinite(duration):
            p, v = p + v * duration + 0.5 * a * duration * duration, v + a * duration
            tau += duration
    return _Profile(kind, t0, segments, target)


def plan_ramp(p0: float, v0: float, target: float, vmax: float, amax: float
              ) -> list[tuple[float, float]]:
    """Trapezoid (or triangle) from position ``p0`` moving at ``v0`` to rest at ``target``.

    Returns ``[(duration, acceleration), ...]``. If the module moves away from the target,
    or too fast to stop before it, it first brakes to rest and then ramps back; if it is
    faster than ``vmax`` it first slows down to ``vmax``.
    """
    pieces: list[tuple[float, float]] = []
    distance = target - p0
    if v0 != 0 and (v0 * distance < 0 or v0 * v0 / (2 * amax) > abs(distance) + 1e-12):
        brake = abs(v0) / amax
        pieces.append((brake, -math.copysign(amax, v0)))
        p0 += v0 * brake / 2
        v0 = 0.0
        distance = target - p0
    if abs(distance) <= 1e-12:
        return pieces or [(0.0, 0.0)]
    sign = math.copysign(1.0, distance)
    distance = abs(distance)
    speed = v0 * sign  # >= 0 here
    if speed > vmax:
        peak = vmax
        first = ((speed - peak) / amax, -sign * amax)
        d1 = (speed * speed - peak * peak) / (2 * amax)
    else:
        peak = min(vmax, math.sqrt(amax * distance + speed * speed / 2))
        first = ((peak - speed) / amax, sign * amax)
        d1 = (peak * peak - speed * speed) / (2 * amax)
    d3 = peak * peak / (2 * amax)
    cruise = max(distance - d1 - d3, 0.0) / peak
    for duration, a in (first, (cruise, 0.0), (peak / amax, -sign * amax)):
        if duration > 0:
            pieces.append((duration, a))
    return pieces


def _first_exit(segment: _Segment, tau_from: float, tau_to: float, lo: float, hi: float
                ) -> tuple[float, float] | None:
    """Earliest ``(tau, limit)`` in [tau_from, tau_to] (segment-local) where the motion
    passes a limit *outward*; None if it does not."""
    best: tuple[float, float] | None = None
    p, v, a = segment.p, segment.v, segment.a
    for level, limit, direction in ((lo - _LIMIT_EPS, lo, -1.0), (hi + _LIMIT_EPS, hi, 1.0)):
        # Already beyond this limit and heading further out: stop at once.
        p_from = p + v * tau_from + 0.5 * a * tau_from * tau_from
        v_from = v + a * tau_from
        if (p_from - level) * direction > 0 and (v_from * direction > 0
                                                 or (v_from == 0 and a * direction > 0)):
            return tau_from, limit
        if a == 0:
            if v == 0:
                continue
            roots: tuple[float, ...] = ((level - p) / v,)
        else:
            disc = v * v + 2 * a * (level - p)
            if disc < 0:
                continue
            root = math.sqrt(disc)
            first, second = (-v - root) / a, (-v + root) / a
            roots = (second, first) if second < first else (first, second)  # sorted()
        for tau in roots:
            if tau_from <= tau <= tau_to and (v + a * tau) * direction > 0:
                if best is None or tau < best[0]:
                    best = (tau, limit)
                break
    return best


# --------------------------------------------------------------------------------------
# The module


@dataclass
class _HeldMotion:
    """A motion command waiting for the StartMove broadcast (Config SYNC_MOTION)."""

    mode: MotionMode
    value: float  # rad, rad/s (already converted from ticks)
    time_ms: int | None
    vmax: float
    amax: float


#: ParamId members as module constants: the SimModule methods run for every frame,
#: and an Enum class attribute costs several times a global lookup.
_P_ACT_POS = ParamId.ACT_POS
_P_ACT_POS_PREV = ParamId.ACT_POS_PREV
_P_ACT_VEL = ParamId.ACT_VEL
_P_CONFIG = ParamId.CONFIG
_P_CUBE_STATE = ParamId.CUBE_STATE
_P_CUR = ParamId.CUR
_P_DEF_MAX_ACC = ParamId.DEF_MAX_ACC
_P_DEF_MAX_CUR = ParamId.DEF_MAX_CUR
_P_DEF_MAX_VEL = ParamId.DEF_MAX_VEL
_P_DELTA_POS = ParamId.DELTA_POS
_P_DIO_SETUP = ParamId.DIO_SETUP
_P_FPOS_STATE_DIO = ParamId.FPOS_STATE_DIO
_P_FSAVE_POS = ParamId.FSAVE_POS
_P_INC_RATIO = ParamId.INC_RATIO
_P_IPOL_POS = ParamId.IPOL_POS
_P_IPOL_VEL = ParamId.IPOL_VEL
_P_MAX_ACC = ParamId.MAX_ACC
_P_MAX_CUR = ParamId.MAX_CUR
_P_MAX_POS = ParamId.MAX_POS
_P_MAX_VEL = ParamId.MAX_VEL
_P_MIN_POS = ParamId.MIN_POS
_P_MOT_CUR = ParamId.MOT_CUR
_P_MOVE_MODE = ParamId.MOVE_MODE
_P_RAW_CUR = ParamId.RAW_CUR
_P_RAW_MOT_CUR = ParamId.RAW_MOT_CUR
_P_TARGET_ACC = ParamId.TARGET_ACC
_P_TARGET_POS = ParamId.TARGET_POS
_P_TARGET_VEL = ParamId.TARGET_VEL


class SimModule:
    """One PRL module. Call :meth:`handle` with decoded requests; it returns the ack (or None).

    ``t`` arguments default to ``clock.now()``; a time earlier than the module's own
    (a late caller) is treated as the module's current time.
    """

    def __init__(self, module_id: int, clock: Clock, *, position: float = 0.0,
                 options: ModuleOptions | None = None,
                 parameters: Mapping[ParamId, float | int] | None = None) -> None:
        self.module_id = module_id
        self.clock = clock
        self.options = options or ModuleOptions()
        self._params = default_parameters(module_id)
        self._params.update(parameters or {})
        for param, value in self._params.items():  # the module stores float32
            if PARAM_TYPES[param] is WireType.F32:
                self._params[param] = _f32(float(value))
        self._t = clock.now()
        self._rest = float(position)  # position while no profile runs
        self._profile: _Profile | None = None
        self._buffered_step: tuple[float, float] | None = None  # (target, seconds)
        self._held: _HeldMotion | None = None
        self._flags = _F.BRAKEACTIVE
        if self.options.home_ok_at_power_on:
            self._flags = _F.HOME_OK
        self._watchdog_deadline: float | None = None
        self._stuck_at: float | None = None
        self._dead = False
        self._last_target = float(position)
        self._saved_position = float(position)
        #: Acknowledges that do not change, made once (see _fpos_ack).
        self._set_acks: dict[ParamId, SetParamAck] = {}
        self._last_fpos_ack: tuple[tuple, GetParamAck] | None = None

    def __repr__(self) -> str:
        return (f"<SimModule {self.module_id} pos={self.position():.4f} "
                f"state={self.state().describe()}>")

    # -- time ----------------------------------------------------------------------

    def _time(self, t: float | None) -> float:
        return self.clock.now() if t is None else t

    def advance(self, t: float | None = None) -> None:
        """Simulate up to ``t``, handling every event (ramp end, soft limit, watchdog)
        exactly when it happens."""
        if t is None:
            t = self.clock.now()
        while self._t < t:
            if self._profile is None and self._watchdog_deadline is None:
                self._t = t  # nothing can happen (the common case between commands)
                return
            event_time, event, limit = self._next_event(t)
            if event is None:
                self._t = t
                return
            self._t = max(self._t, event_time)
            if event is _SOFT_LIMIT:
                self._soft_limit_reached(limit)
            elif event is _PROFILE_END:
                self._profile_finished()
            else:
                self._watchdog_expired()

    def _next_event(self, horizon: float) -> tuple[float, str | None, float]:
        """(time, kind, limit) of the first event up to ``horizon``; kind None if none.
        Of events at the same time, the watchdog comes first, then the end of the
        profile, then a soft limit."""
        if self._dead:
            return 0.0, None, 0.0
        best_time, best, best_limit = 0.0, None, 0.0
        deadline = self._watchdog_deadline
        if deadline is not None and deadline <= horizon:
            best_time, best = deadline, _WATCHDOG
        profile = self._profile
        if profile is not None:
            end = profile.end
            if end <= horizon and (best is None or end < best_time):
                best_time, best = end, _PROFILE_END
            if self._stuck_at is None:
                until = min(horizon, end)
                exit_ = self._limit_exit(profile, until)
                if exit_ is not None:
                    at, limit = exit_
                    if at <= horizon and (best is None or at < best_time):
                        best_time, best, best_limit = at, _SOFT_LIMIT, limit
        return best_time, best, best_limit

    def _limit_exit(self, profile: _Profile, until: float) -> tuple[float, float] | None:
        lo, hi = self._params[_P_MIN_POS], self._params[_P_MAX_POS]
        # A profile that stays clear inside the limits everywhere crosses none (the
        # common case, looked at on every frame while a module moves): the search below
        # would find no root and nothing beyond, since its positions are the profile's
        # ones up to rounding, far less than the clearance asked for here.
        span = profile.span()
        if span is not None and lo - _LIMIT_EPS + _CLEAR < span[0] and (
                span[1] < hi + _LIMIT_EPS - _CLEAR):
            return None
        tau_now, tau_end = self._t - profile.t0, until - profile.t0
        for segment in profile.segments:
            seg_end = segment.t_start + segment.duration
            if seg_end < tau_now:
                continue
            if segment.t_start > tau_end:
                break
            hit = _first_exit(segment, max(tau_now, segment.t_start) - segment.t_start,
                              min(tau_end, seg_end) - segment.t_start, lo, hi)
            if hit is not None:
                return profile.t0 + segment.t_start + hit[0], hit[1]
        return None

    # -- events ----------------------------------------------------------------------

    def _profile_finished(self) -> None:
        profile = self._profile
        assert profile is not None
        self._rest, _, _ = profile.sample(profile.end)
        self._profile = None
        if profile.kind == "home":
            self._homed_on_switch()
        if self._buffered_step is not None:
            target, seconds = self._buffered_step
            self._buffered_step = None
            self._start_step(target, seconds)

    def _soft_limit_reached(self, limit: float) -> None:
        self._stop(_F.BEYOND_SOFT | self.options.soft_limit_flags, at=limit)

    def _watchdog_expired(self) -> None:
        self._watchdog_deadline = None
        self._stop(self.options.watchdog_flags)

    def _stop(self, flags: StateFlag = _NO_FLAGS, at: float | None = None) -> None:
        """Stop at once (velocity 0) at the current or the given position, add ``flags``."""
        self._rest = self._actual_position() if at is None else at
        if self._stuck_at is not None:
            self._stuck_at = self._rest
        self._profile = None
        self._buffered_step = None
        self._held = None
        self._flags |= flags

    # -- state -----------------------------------------------------------------------

    def _commanded(self) -> tuple[float, float, _Segment | None]:
        if self._profile is None:
            return self._rest, 0.0, None
        return self._profile.sample(self._t)

    def _actual_position(self) -> float:
        if self._stuck_at is not None:
            return self._stuck_at
        return self._commanded()[0]

    def _actual_velocity(self) -> float:
        if self._stuck_at is not None:
            return 0.0
        return self._commanded()[1]

    def _state_bits(self) -> int:
        # Plain ints on this path: it runs for every FPosStateDio read, and IntFlag
        # arithmetic costs microseconds per operation.
        state = int(self._flags) & ~_MOTION_MASK
        profile = self._profile
        if profile is None:
            return state | _RAMP_END
        _, _, segment = profile.sample(self._t)
        state |= _MOTION
        if profile.kind == "step":
            state |= _INPROGRESS | (_FULLBUFFER if self._buffered_step is not None else 0)
        else:
            state |= int(segment.phase)
        return state

    def _state_now(self) -> StateFlag:
        return StateFlag(self._state_bits())

    def _short_state_now(self) -> ShortState:
        state = self._state_bits()
        short = 0x01 if state & _ERROR_OR_HALTED or not state & _HOME_OK else 0
        short |= (state >> 5) & 0x0E  # SWR, SW1, SW2 (0x40, 0x80, 0x100) -> 0x02, 0x04, 0x08
        if state & _MOTION:
            short |= 0x10
        if state & _RAMP_END:
            short |= 0x20
        if state & _INPROGRESS:
            short |= 0x40
        if state & _FULLBUFFER:
            short |= 0x80
        return _SHORT_STATES[short]

    def _dio(self) -> int:
        return int(self._params.get(_P_DIO_SETUP, 0)) & 0xFF

    def state(self, t: float | None = None) -> StateFlag:
        """The 32-bit state word (CubeState) at ``t``."""
        self.advance(t)
        return self._state_now()

    def short_state(self, t: float | None = None) -> ShortState:
        self.advance(t)
        return self._short_state_now()

    def position(self, t: float | None = None) -> float:
        """Actual joint position (rad, module coordinates) at ``t``."""
        self.advance(t)
        return self._actual_position()

    def velocity(self, t: float | None = None) -> float:
        self.advance(t)
        return self._actual_velocity()

    def parameter(self, param: ParamId, t: float | None = None) -> float | int | PosStateDio:
        """What GetExtended ``param`` would answer at ``t``."""
        self.advance(t)
        return self._read(param)

    @property
    def is_dead(self) -> bool:
        """True once the module went missing (unplugged): it never answers again."""
        return self._dead

    def set_position(self, position: float, t: float | None = None) -> None:
        """Put the joint at ``position`` at rest (a test's starting pose); keeps the state."""
        self.advance(t)
        self._profile = None
        self._buffered_step = None
        self._held = None
        self._rest = float(position)
        self._last_target = float(position)
        if self._stuck_at is not None:
            self._stuck_at = self._rest

    # -- faults (see seqrun.sim.faults) ------------------------------------------------

    def inject(self, kind: str, t: float | None = None) -> None:
        """Apply a fault that changes the module itself (tow_error, halt, stuck, missing).

        Faults about acknowledges (no_ack, drop_acks) are the arm's business.
        """
        self.advance(t)
        if kind == "tow_error":
            self._stop(_F.ERROR | _F.TOW_ERROR | _F.HALTED)
        elif kind == "halt":
            self._stop(_F.HALTED)
        elif kind == "stuck":
            self._stuck_at = self._actual_position()
        elif kind == "missing":
            self._stop()
            self._watchdog_deadline = None
            self._dead = True
        elif kind not in ("no_ack", "drop_acks"):
            raise ValueError(f"unknown fault kind {kind!r}")

    # -- requests ----------------------------------------------------------------------

    def handle(self, request: Request, t: float | None = None) -> Ack | None:
        """Process one decoded request at ``t``; returns its acknowledge, or None
        (broadcasts, suppressed acks, a missing module)."""
        self.advance(t)
        if self._dead:
            return None
        if isinstance(request, BroadcastRequest):
            self._broadcast(request)
            return None
        if isinstance(request, GetParam):
            if request.param is _P_FPOS_STATE_DIO:
                ack: Ack | None = self._fpos_ack()
            else:
                ack = GetParamAck(self.module_id, request.param, self._read(request.param))
        elif isinstance(request, SetParam):
            self._write(request.param, request.value)
            ack = self._set_acks.get(request.param)
            if ack is None:
                ack = self._set_acks[request.param] = SetParamAck(self.module_id, request.param)
        elif isinstance(request, SetMotion):
            ack = self._motion(request)
        elif isinstance(request, CommandRequest):
            ack = self._command(request.command)
        else:
            return None
        if (self.options.honour_disable_ack
                and int(self._params[_P_CONFIG]) & _DISABLE_ACK):
            return None
        return ack

    def _fpos_ack(self) -> GetParamAck:
        """The acknowledge of a GetExtended FPosStateDio now: the previous one again while
        the reading is the same (a module at rest is read every cycle; acknowledges are
        immutable, and the wire encodes the same object only once)."""
        reading = self._fpos_reading()
        position = reading[0]
        last = self._last_fpos_ack
        # (0.0 == -0.0, but they are different frames)
        if last is not None and last[0] == reading and (
                position or math.copysign(1.0, position) == math.copysign(1.0, last[0][0])):
            return last[1]
        ack = GetParamAck(self.module_id, _P_FPOS_STATE_DIO, PosStateDio(*reading))
        self._last_fpos_ack = (reading, ack)
        return ack

    def _broadcast(self, request: BroadcastRequest) -> None:
        command = request.command
        if command in (CommandId.RESET, CommandId.HOME, CommandId.HALT):
            self._command(command)
        elif command == CommandId.WATCHDOG_REFRESH:
            self._refresh_watchdog()
        elif command == CommandId.START_MOVE:
            held, self._held = self._held, None
            if held is not None and not self._refusal(held.mode, held.value):
                self._execute(held)
        elif command == CommandId.SAVE_POS_ALL:
            self._saved_position = self._actual_position()
        # SetBaudAll: accepted, the simulated bus keeps its bitrate.

    def _command(self, command: CommandId) -> Ack | None:
        if command == CommandId.RESET:
            self._stop()
            self._flags &= ~RESETTABLE
            self._watchdog_deadline = None
        elif command == CommandId.HOME:
            if not self._flags & (_F.ERROR | _F.HALTED):
                self._flags &= ~_F.BRAKEACTIVE
                if self.options.homing_travel:
                    self._start_homing()
                else:
                    # A PRL has absolute encoders: Home enables the motor (the click), no
                    # travel.
                    self._flags |= _F.HOME_OK
        elif command == CommandId.HALT:
            self._stop(_F.HALTED)
        elif command == CommandId.WATCHDOG_REFRESH:
            self._refresh_watchdog(addressed=True)
            if not self.options.ack_addressed_watchdog:
                return None
        # TOGGLE_HOME, RECALC_PID, SAVE_PARAMS, RESET_TIME: acknowledged, no simulated effect.
        return CommandAck(self.module_id, command)

    def _start_homing(self) -> None:
        """Travel to the home switch (``homing_travel``): HOME_OK clear until there."""
        self._flags &= ~(_F.HOME_OK | _F.SWR)
        self._buffered_step = self._held = None
        position, velocity, _ = self._commanded()
        target = self.options.home_switch_position
        vmax = abs(float(self._params[ParamId.FHOME_VEL])) or 0.1
        amax = abs(float(self._params[ParamId.DEF_HOME_ACC])) or 0.5
        pieces = plan_ramp(position, velocity, target, vmax, amax)
        self._start(_build_profile("home", self._t, position, velocity, pieces, target),
                    rest=target)
        if self._profile is None:  # already on the switch
            self._homed_on_switch()

    def _homed_on_switch(self) -> None:
        self._flags |= _F.HOME_OK | _F.SWR

    def _refresh_watchdog(self, addressed: bool = False) -> None:
        if self.options.addressed_refresh_arms_watchdog:
            if addressed:
                self._params[_P_CONFIG] = int(self._params[_P_CONFIG]) | _WATCHDOG_ENABLE
            elif self._watchdog_deadline is None:
                return  # a broadcast does not arm it
        if int(self._params[_P_CONFIG]) & _WATCHDOG_ENABLE:
            self._watchdog_deadline = self._t + self.options.watchdog_timeout

    # -- parameters ----------------------------------------------------------------------

    def _inc_ratio(self) -> float:
        ratio = float(self._params[_P_INC_RATIO])
        return ratio if ratio > 0 else 1.0

    def _fpos_reading(self) -> tuple[float, ShortState, int]:
        """FPosStateDio's fields now: position (float32), short state, digital inputs."""
        return _f32(self._actual_position()), self._short_state_now(), self._dio()

    def _read(self, param: ParamId) -> float | int | PosStateDio:
        if param is _P_FPOS_STATE_DIO:  # first: the reads of every control cycle
            return PosStateDio(*self._fpos_reading())
        wire = PARAM_TYPES[param]
        if param in _TICK_TWINS:
            value = float(self._read(_TICK_TWINS[param]))  # type: ignore[arg-type]
            return _fit_int(round(value / self._inc_ratio()), wire)
        live = self._live_value(param)
        value = live if live is not None else self._params.get(param, 0)
        if wire is WireType.F32:
            return _f32(float(value))
        return _fit_int(int(value), wire)

    def _live_value(self, param: ParamId) -> float | int | None:
        if param in (_P_ACT_POS, _P_ACT_POS_PREV):
            return self._actual_position()
        if param == _P_ACT_VEL:
            return self._actual_velocity()
        if param in (_P_IPOL_POS, _P_IPOL_VEL, _P_DELTA_POS):
            commanded, velocity, _ = self._commanded()
            if param == _P_IPOL_POS:
                return commanded
            if param == _P_IPOL_VEL:
                return velocity
            return commanded - self._actual_position()
        if param == _P_CUBE_STATE:
            return int(self._state_now())
        if param == _P_TARGET_POS:
            return self._last_target
        if param == _P_FSAVE_POS:
            return self._saved_position
        if param == _P_MOVE_MODE:
            return int(self._profile_mode())
        if param in (_P_CUR, _P_MOT_CUR):
            return self._current()
        if param in (_P_RAW_CUR, _P_RAW_MOT_CUR):
            max_cur = float(self._params[_P_MAX_CUR]) or 1.0
            return round(500 * self._current() / max_cur)
        return None

    def _profile_mode(self) -> MotionMode | int:
        if self._profile is None:
            return 0
        return {"ramp": MotionMode.FRAMP, "step": MotionMode.FSTEP,
                "velocity": MotionMode.FVEL}.get(self._profile.kind, 0)

    def _current(self) -> float:
        """The motor model's current now (:meth:`required_current`), at most MaxCur: 0 at
        rest, growing with acceleration and speed."""
        if self._profile is None or self._stuck_at is not None:
            return 0.0
        _, velocity, segment = self._profile.sample(self._t)
        need = self.required_current(segment.a, velocity)
        max_cur = abs(float(self._params[_P_MAX_CUR]))
        return max(-max_cur, min(max_cur, need))

    def required_current(self, acceleration: float, velocity: float) -> float:
        """Amperes a motion at ``acceleration`` (rad/s^2) and ``velocity`` (rad/s) needs
        (the motor model, module docstring); signed like the acceleration, else the
        velocity."""
        params = self._params
        rated = float(params[_P_DEF_MAX_CUR])
        need = rated * (CURRENT_PER_ACCELERATION * abs(acceleration)
                        / (float(params[_P_DEF_MAX_ACC]) or 1.0)
                        + CURRENT_PER_VELOCITY * abs(velocity)
                        / (float(params[_P_DEF_MAX_VEL]) or 1.0))
        return math.copysign(need, acceleration if acceleration else velocity)

    def _current_scale(self, vmax: float, amax: float) -> float:
        """1 when a motion bounded by ``vmax``/``amax`` stays within MaxCur, else the
        factor both must shrink by (CURLIMIT set); 0 when the module stopped instead
        (``current_limit_halts``)."""
        need = abs(self.required_current(amax, 0.0)) + abs(self.required_current(0.0, vmax))
        max_cur = float(self._params[_P_MAX_CUR])
        if need <= max_cur:
            return 1.0
        if self.options.current_limit_halts or max_cur <= 0:
            self._stop(_F.CURLIMIT | _F.ERROR)
            return 0.0
        self._flags |= _F.CURLIMIT
        return max_cur / need

    def _write(self, param: ParamId, value: float) -> None:
        if param not in WRITABLE_PARAMS:
            return  # acknowledged, ignored (read-only on the module)
        if param in _TICK_TWINS:
            param, value = _TICK_TWINS[param], value * self._inc_ratio()
        if param == _P_TARGET_POS:
            return  # TargetPosInc: no effect in the simulation
        if PARAM_TYPES[param] is WireType.F32:
            value = _f32(float(value))
        self._params[param] = value
        if param == ParamId.FHOME_VEL and self.options.fhome_vel_saved_on_write:
            self._params[ParamId.DEF_HOME_VEL] = value
        if param == _P_CONFIG and not int(value) & ConfigFlag.WATCHDOG_ENABLE:
            self._watchdog_deadline = None

    # -- motion --------------------------------------------------------------------------

    def _limits(self) -> tuple[float, float]:
        return float(self._params[_P_MIN_POS]), float(self._params[_P_MAX_POS])

    def _motion(self, request: SetMotion) -> Ack | None:
        mode = request.mode
        base, base_is_float, is_extended_ack, is_float = _MODE_FACTS[mode]
        position_at_receipt = self._actual_position()
        short_at_receipt = self._short_state_now()
        value = float(request.value)
        if not base_is_float:
            value *= self._inc_ratio()  # ticks, ticks/s -> rad, rad/s
        refusal = self._refusal(base, value)
        if refusal is None:
            motion = _HeldMotion(base, value, request.time_ms,
                                 vmax=min(float(self._params[_P_TARGET_VEL]),
                                          float(self._params[_P_MAX_VEL])),
                                 amax=min(float(self._params[_P_TARGET_ACC]),
                                          float(self._params[_P_MAX_ACC])))
            if int(self._params[_P_CONFIG]) & _SYNC_MOTION:
                self._held = motion
            else:
                self._execute(motion)
        elif not self.options.ack_refused_motion:
            return None
        if not is_extended_ack:
            return MotionAck(self.module_id, mode)
        state = _SHORT_STATES[int(short_at_receipt) | (_NOT_OK if refusal else 0)]
        position: float | int = _f32(position_at_receipt)
        if not is_float:
            position = _fit_int(round(position_at_receipt / self._inc_ratio()), WireType.I32)
        return MotionExtAck(self.module_id, mode, position, state, self._dio())

    def _refusal(self, mode: MotionMode, value: float) -> str | None:
        """Why the module does not accept this motion now, or None."""
        flags = int(self._flags)
        if flags & _FAULTS:
            return f"module in {(self._flags & StateFlag.FAULTS).describe()}"
        if not flags & _HOME_OK:
            return "not homed"
        if mode not in _SIMULATED_MODES:
            return f"{mode.name} is not simulated"
        if not math.isfinite(value):
            return "value is not finite"
        position = self._actual_position()
        lo, hi = self._limits()
        if mode in _VELOCITY_MODES:
            if (value < 0 and position <= lo) or (value > 0 and position >= hi):
                return "would move further beyond a soft limit"
        else:
            target = min(max(value, lo), hi)
            # Clamped targets always lie inside, so this only refuses a limit pair that
            # is inverted (MinPos > MaxPos) and would push the joint outward.
            if target < position <= lo or target > position >= hi:
                return "would move further beyond a soft limit"
        if mode in _RAMP_OR_VELOCITY_MODES:
            vmax = min(float(self._params[_P_TARGET_VEL]),
                       float(self._params[_P_MAX_VEL]))
            amax = min(float(self._params[_P_TARGET_ACC]),
                       float(self._params[_P_MAX_ACC]))
            if amax <= 0 or (mode in _RAMP_MODES and vmax <= 0):
                return "TargetVel/TargetAcc or MaxVel/MaxAcc is zero"
        return None

    def _execute(self, motion: _HeldMotion) -> None:
        """Start an accepted motion now (at ``self._t``)."""
        lo, hi = self._limits()
        if motion.mode in _STEP_MODES:
            position = self._commanded()[0]
            target = min(max(motion.value, lo), hi)
            step_s = (motion.time_ms or 0) / 1000.0
            speed = abs(target - position) / step_s if step_s > 0 else float(
                self._params[_P_MAX_VEL])
            scale = self._current_scale(speed, 0.0)
        else:
            scale = self._current_scale(motion.vmax, motion.amax)
        if scale == 0.0:
            return  # stopped at the current limit (current_limit_halts)
        if scale < 1.0:
            motion = _HeldMotion(motion.mode, motion.value, motion.time_ms,
                                 vmax=motion.vmax * scale, amax=motion.amax * scale)
        # Plans start from the setpoint (position and velocity); for a stuck joint that is
        # where the controller believes it is, not where the joint is.
        position, velocity, _ = self._commanded()
        if motion.mode in _STEP_MODES:
            target = min(max(motion.value, lo), hi)
            seconds = (motion.time_ms or 0) / 1000.0 / scale
            self._last_target = target
            running_step = self._profile is not None and self._profile.kind == "step"
            if running_step and self.options.step_buffering:
                self._buffered_step = (target, seconds)
            else:
                self._buffered_step = None
                self._start_step(target, seconds)
            return
        self._buffered_step = None
        if motion.mode in _RAMP_MODES:
            target = min(max(motion.value, lo), hi)
            self._last_target = target
            if self.options.framp_from_standstill:
                velocity = 0.0
            pieces = plan_ramp(position, velocity, target, motion.vmax, motion.amax)
            self._start(_build_profile("ramp", self._t, position, velocity, pieces, target))
        else:
            vmax = float(self._params[_P_MAX_VEL]) * scale
            wanted = min(max(motion.value, -vmax), vmax)
            if self.options.velocity_mode_acceleration:
                change = abs(wanted - velocity) / motion.amax
                accel = math.copysign(motion.amax, wanted - velocity)
                pieces = [(change, accel)] if change > 0 else []
            else:
                pieces, velocity = [], wanted
            if wanted != 0:
                pieces.append((math.inf, 0.0))
                self._start(_build_profile("velocity", self._t, position, velocity, pieces, None))
            elif pieces:
                stop_at = position + velocity * pieces[0][0] / 2
                self._start(_build_profile("velocity", self._t, position, velocity, pieces,
                                           stop_at))
            else:
                self._start(None, rest=position)

    def _start_step(self, target: float, seconds: float) -> None:
        position = self._commanded()[0]
        vmax = float(self._params[_P_MAX_VEL])
        distance = target - position
        if vmax > 0:
            seconds = max(seconds, abs(distance) / vmax)
        if seconds <= 0:
            self._start(None, rest=target)
            return
        self._start(_build_profile("step", self._t, position, distance / seconds,
                                   [(seconds, 0.0)], target))

    def _start(self, profile: _Profile | None, rest: float | None = None) -> None:
        # Leaves the home switch (set again by homing's end). (Tested on a plain int
        # first: IntFlag arithmetic is several Python-level calls, and this runs for
        # every motion command; with SWR clear the flags stay what they are.)
        if int(self._flags) & _SWR:
            self._flags &= ~_F.SWR
        if profile is not None and profile.end <= self._t:  # nothing to do: already there
            rest, profile = profile.sample(profile.end)[0], None
        self._profile = profile
        if profile is None and rest is not None:
            self._rest = rest


_F32_PACK, _F32_UNPACK = struct.Struct("<f").pack, struct.Struct("<f").unpack


def _f32(value: float) -> float:
    """Round to float32 like the module's arithmetic (and the wire)."""
    try:
        return _F32_UNPACK(_F32_PACK(value))[0]
    except OverflowError:
        return math.copysign(math.inf, value)


def _fit_int(value: int, wire: WireType) -> int:
    lo, hi = wire.minimum, wire.maximum
    if lo is None or hi is None:
        return value
    return min(max(value, lo), hi)
