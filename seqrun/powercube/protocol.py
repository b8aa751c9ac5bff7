"""PowerCube (Schunk/Amtec PRL, LWA 3) CAN protocol constants: ids, commands, parameters,
motion modes, parameter wire types and the state / config flag words.

Pure data, no I/O. The frame layouts that use these constants live in
:mod:`seqrun.powercube.codec`; the facts (and their sources) are collected in
``/work/shared/reference/powercube-protocol.md``.

All payloads are little endian, all frames standard 11-bit. Module ids are 1..31
(``0x0C0 + 32`` would collide with ``0x0E0``).
"""

from __future__ import annotations

import enum
import struct
from enum import IntEnum, IntFlag

#: Acknowledge / reply from module ``m`` arrives on ``ACK_BASE + m``.
ACK_BASE = 0x0A0
#: GetExtended requests go to ``GET_BASE + m``.
GET_BASE = 0x0C0
#: Every other addressed request goes to ``SET_BASE + m``.
SET_BASE = 0x0E0
#: "Command all" broadcasts; modules never acknowledge them.
BROADCAST_ID = 0x100
#: 4-byte state word frames from module ``m`` (when a module sends them is undocumented).
STATE_BASE = 0x060

#: Valid module ids.
MIN_MODULE_ID = 1
MAX_MODULE_ID = 31
MODULE_IDS = range(MIN_MODULE_ID, MAX_MODULE_ID + 1)

#: Trailer byte of the short acknowledges (an "OK" marker, not an echo).
ACK_OK = 0x64


class _Describe:
    """``describe()`` for the flag enums: ``"ERROR|HALTED|TOW_ERROR"``."""

    def describe(self) -> str:
        value = int(self)  # type: ignore[call-overload]
        if value == 0:
            return "none"
        names = []
        known = 0
        # Iterating a Flag class yields only the single-bit (canonical) members, in bit order.
        for member in type(self):  # type: ignore[attr-defined]
            if value & member.value:
                names.append(member.name)
                known |= member.value
        unknown = value & ~known
        if unknown:
            names.append(f"0x{unknown:X}")
        return "|".join(names)


class CommandId(IntEnum):
    """Byte 0 of every request and acknowledge.

    ``SET_BAUD_ALL`` (broadcast only) shares the code 0x09 with ``RECALC_PID`` (addressed
    only), so it is an alias: ``CommandId(0x09).name == "RECALC_PID"``. Likewise
    ``SYNC_MOTION_ALL`` is an alias of ``START_MOVE``.
    """

    RESET = 0x00
    HOME = 0x01
    HALT = 0x02
    TOGGLE_HOME = 0x03
    INTERNAL = 0x04
    WATCHDOG_REFRESH = 0x07
    SET_EXTENDED = 0x08
    RECALC_PID = 0x09
    SET_BAUD_ALL = 0x09
    GET_EXTENDED = 0x0A
    SET_MOTION = 0x0B
    SET_ISTEP = 0x0D
    SAVE_POS_ALL = 0x0E
    START_MOVE = 0x0F
    SYNC_MOTION_ALL = 0x0F
    SAVE_PARAMS = 0x10
    RESET_TIME = 0x12


#: One-byte commands that may be addressed to a module (``0x0E0+m : [cmd]``) and are
#: acknowledged with ``[cmd, 0x64]``. WATCHDOG_REFRESH is sent addressed once by the KTH
#: driver to arm the watchdog.
ADDRESSED_COMMANDS: frozenset[CommandId] = frozenset({
    CommandId.RESET, CommandId.HOME, CommandId.HALT, CommandId.TOGGLE_HOME,
    CommandId.WATCHDOG_REFRESH, CommandId.RECALC_PID, CommandId.SAVE_PARAMS,
    CommandId.RESET_TIME,
})

#: Commands that may be broadcast on ``0x100`` (``[cmd]`` or ``[cmd, arg]``).
BROADCAST_COMMANDS: frozenset[CommandId] = frozenset({
    CommandId.RESET, CommandId.HOME, CommandId.HALT, CommandId.WATCHDOG_REFRESH,
    CommandId.SET_BAUD_ALL, CommandId.SAVE_POS_ALL, CommandId.START_MOVE,
})


class ParamId(IntEnum):
    """Parameter ids (byte 1 of SetExtended / GetExtended), section C of the reference.

    ``DEF_*`` are factory defaults (read only on a healthy module); ``I*`` are the integer
    (encoder tick) twins of float parameters. Units of the float ones: rad, rad/s, rad/s²,
    A, V, °C.
    """

    DEF_HOME_OFFSET = 0x00
    DEF_GEAR_RATIO = 0x01
    DEF_LIN_RATIO = 0x02
    DEF_MIN_POS = 0x03
    DEF_MAX_POS = 0x04
    DEF_MAX_DELTA_POS = 0x05
    DEF_MAX_DELTA_VEL = 0x06
    DEF_CUR_OFFSET = 0x07
    DEF_TORQUE_RATIO = 0x07  # RobWork/KTH/Bosch name for the same id
    DEF_CUR_RATIO = 0x08
    DEF_MIN_VEL = 0x09
    DEF_MAX_VEL = 0x0A
    DEF_MIN_ACC = 0x0B
    DEF_MAX_ACC = 0x0C
    DEF_MIN_CUR = 0x0D
    DEF_MAX_CUR = 0x0E
    DEF_HOME_VEL = 0x0F
    DEF_HOME_ACC = 0x10
    DEF_DIO_DATA = 0x19
    DEF_CUBE_SERIAL = 0x1A
    DEF_CONFIG = 0x1B
    DEF_PULSES_PER_TURN = 0x1C
    DEF_CUBE_VERSION = 0x1D
    DEF_SERVICE_INTERVAL = 0x1E
    DEF_BRAKE_TIMEOUT = 0x1F
    DEF_ADDRESS = 0x20
    DEF_PRIM_BAUD = 0x22
    DEF_SCND_BAUD = 0x23
    POS_COUNT = 0x24
    REF_POS_COUNT = 0x25
    DIO_SETUP = 0x26
    ACT_DIO_DATA = 0x26  # m5api getDioData reads this id
    CUBE_STATE = 0x27
    TARGET_POS_INC = 0x28
    TARGET_VEL_INC = 0x29
    TARGET_ACC_INC = 0x2A
    STEP_INC = 0x2B
    HOME_OFFSET_INC = 0x2C
    RAW_CUR = 0x35
    HOME_TO_ZERO_INC = 0x36
    CONFIG = 0x39
    MOVE_MODE = 0x3A
    INC_RATIO = 0x3B
    ACT_POS = 0x3C
    ACT_POS_PREV = 0x3D
    IPOL_POS = 0x3E
    DELTA_POS = 0x3F
    MAX_DELTA_POS = 0x40
    ACT_VEL = 0x41
    IPOL_VEL = 0x42
    MIN_POS = 0x45
    MAX_POS = 0x46
    MAX_VEL = 0x48
    MAX_ACC = 0x4A
    MAX_CUR = 0x4C
    CUR = 0x4D
    TARGET_POS = 0x4E
    TARGET_VEL = 0x4F
    TARGET_ACC = 0x50
    DEF_C0 = 0x51
    DEF_DAMP = 0x52
    DEF_A0 = 0x53
    ACT_C0 = 0x54
    ACT_DAMP = 0x55
    ACT_A0 = 0x56
    DEF_BURN_COUNT = 0x57
    SETUP = 0x58
    HOME_OFFSET = 0x59
    IPOS = 0x5A
    IMAX_DELTA_POS = 0x5B
    IMIN_POS = 0x5C
    IMAX_POS = 0x5D
    IMAX_VEL = 0x5E
    IMAX_ACC = 0x5F
    IVEL = 0x60
    IDELTA_POS = 0x61
    FPOS_STATE_DIO = 0x62
    FSAVE_POS = 0x63
    FHOME_VEL = 0x64
    IHOME_VEL = 0x65
    SYNC_TIME = 0x66
    LOAD_LIMIT = 0x67
    MAX_LOAD_GRADIENT = 0x68
    LOAD_DELTA_TIME = 0x69
    RAW_MOT_CUR = 0x6C
    RAW_MOT_SUPPLY = 0x6D
    RAW_TEMP = 0x6E
    RAW_LOGIC_SUPPLY = 0x6F
    MOT_CUR = 0x70
    MOT_SUPPLY = 0x71
    TEMP = 0x72
    LOGIC_SUPPLY = 0x73
    MIN_LOGIC = 0x74
    MAX_LOGIC = 0x75
    MIN_MOTOR = 0x76
    MAX_MOTOR = 0x77
    NOM_CUR = 0x78
    HMAX_CUR = 0x79
    LOGIC_UNDERSHOOT_TIME = 0x7A
    LOGIC_OVERSHOOT_TIME = 0x7B
    MOTOR_UNDERSHOOT_TIME = 0x7C
    MOTOR_OVERSHOOT_TIME = 0x7D
    NOM_CUR_OVERSHOOT_TIME = 0x7E
    HMAX_CUR_OVERSHOOT_TIME = 0x7F
    KP_PWM_LIMIT = 0x80
    CURRENT_LIMIT = 0x81
    MAX_PWM_OUTPUT = 0x82


class WireType(enum.Enum):
    """How a value is laid out on the wire (little endian).

    ``F32_U8_U8`` is the composite of parameter 0x62 FPosStateDio: position, short state,
    dio.
    """

    F32 = ("<f", None, None)
    I32 = ("<i", -(2**31), 2**31 - 1)
    U32 = ("<I", 0, 2**32 - 1)
    I16 = ("<h", -(2**15), 2**15 - 1)
    U16 = ("<H", 0, 2**16 - 1)
    U8 = ("<B", 0, 2**8 - 1)
    F32_U8_U8 = ("<fBB", None, None)

    def __init__(self, fmt: str, minimum: int | None, maximum: int | None) -> None:
        #: ``struct`` format (little endian).
        self.fmt = fmt
        #: Precompiled :class:`struct.Struct` for ``fmt``.
        self.struct = struct.Struct(fmt)
        #: Encoded size in bytes.
        self.size = self.struct.size
        #: Integer range (None for float and composite types).
        self.minimum = minimum
        self.maximum = maximum

    @property
    def is_float(self) -> bool:
        return self is WireType.F32

    @property
    def is_int(self) -> bool:
        return self.minimum is not None


_F, _I32, _U32, _I16, _U16, _U8 = (WireType.F32, WireType.I32, WireType.U32, WireType.I16,
                                   WireType.U16, WireType.U8)

#: Wire type of every parameter.
PARAM_TYPES: dict[ParamId, WireType] = {
    **{p: _F for p in (
        ParamId.DEF_HOME_OFFSET, ParamId.DEF_GEAR_RATIO, ParamId.DEF_LIN_RATIO,
        ParamId.DEF_MIN_POS, ParamId.DEF_MAX_POS, ParamId.DEF_MAX_DELTA_POS,
        ParamId.DEF_MAX_DELTA_VEL, ParamId.DEF_CUR_OFFSET, ParamId.DEF_CUR_RATIO,
        ParamId.DEF_MIN_VEL, ParamId.DEF_MAX_VEL, ParamId.DEF_MIN_ACC, ParamId.DEF_MAX_ACC,
        ParamId.DEF_MIN_CUR, ParamId.DEF_MAX_CUR, ParamId.DEF_HOME_VEL, ParamId.DEF_HOME_ACC,
        ParamId.INC_RATIO, ParamId.ACT_POS, ParamId.ACT_POS_PREV, ParamId.IPOL_POS,
        ParamId.DELTA_POS, ParamId.MAX_DELTA_POS, ParamId.ACT_VEL, ParamId.IPOL_VEL,
        ParamId.MIN_POS, ParamId.MAX_POS, ParamId.MAX_VEL, ParamId.MAX_ACC, ParamId.MAX_CUR,
        ParamId.CUR, ParamId.TARGET_POS, ParamId.TARGET_VEL, ParamId.TARGET_ACC,
        ParamId.HOME_OFFSET, ParamId.FSAVE_POS, ParamId.FHOME_VEL,
        ParamId.MOT_CUR, ParamId.MOT_SUPPLY, ParamId.TEMP, ParamId.LOGIC_SUPPLY,
        ParamId.MIN_LOGIC, ParamId.MAX_LOGIC, ParamId.MIN_MOTOR, ParamId.MAX_MOTOR,
        ParamId.NOM_CUR, ParamId.HMAX_CUR, ParamId.CURRENT_LIMIT,
    )},
    **{p: _U32 for p in (
        ParamId.DEF_DIO_DATA, ParamId.DEF_CUBE_SERIAL, ParamId.DEF_CONFIG,
        ParamId.DEF_PULSES_PER_TURN, ParamId.DIO_SETUP, ParamId.CUBE_STATE, ParamId.CONFIG,
        ParamId.SETUP,
    )},
    **{p: _I32 for p in (
        ParamId.POS_COUNT, ParamId.REF_POS_COUNT, ParamId.TARGET_POS_INC,
        ParamId.TARGET_VEL_INC, ParamId.TARGET_ACC_INC, ParamId.STEP_INC,
        ParamId.HOME_OFFSET_INC, ParamId.HOME_TO_ZERO_INC,
        ParamId.IPOS, ParamId.IMAX_DELTA_POS, ParamId.IMIN_POS, ParamId.IMAX_POS,
        ParamId.IMAX_VEL, ParamId.IMAX_ACC, ParamId.IVEL, ParamId.IDELTA_POS,
        ParamId.IHOME_VEL, ParamId.LOAD_LIMIT, ParamId.MAX_LOAD_GRADIENT,
        ParamId.LOGIC_UNDERSHOOT_TIME, ParamId.LOGIC_OVERSHOOT_TIME,
        ParamId.MOTOR_UNDERSHOOT_TIME, ParamId.MOTOR_OVERSHOOT_TIME,
        ParamId.NOM_CUR_OVERSHOOT_TIME, ParamId.HMAX_CUR_OVERSHOOT_TIME,
        ParamId.KP_PWM_LIMIT, ParamId.MAX_PWM_OUTPUT,
    )},
    **{p: _I16 for p in (
        ParamId.RAW_CUR, ParamId.DEF_C0, ParamId.DEF_DAMP, ParamId.DEF_A0, ParamId.ACT_C0,
        ParamId.ACT_DAMP, ParamId.ACT_A0, ParamId.SYNC_TIME, ParamId.RAW_MOT_CUR,
        ParamId.RAW_MOT_SUPPLY, ParamId.RAW_TEMP, ParamId.RAW_LOGIC_SUPPLY,
    )},
    **{p: _U16 for p in (
        ParamId.DEF_CUBE_VERSION, ParamId.DEF_SERVICE_INTERVAL, ParamId.DEF_BRAKE_TIMEOUT,
        ParamId.LOAD_DELTA_TIME,
    )},
    **{p: _U8 for p in (
        ParamId.DEF_ADDRESS, ParamId.DEF_PRIM_BAUD, ParamId.DEF_SCND_BAUD, ParamId.MOVE_MODE,
        ParamId.DEF_BURN_COUNT,
    )},
    ParamId.FPOS_STATE_DIO: WireType.F32_U8_U8,
}

assert set(PARAM_TYPES) == set(ParamId), "every ParamId needs a wire type"


class MotionMode(IntEnum):
    """Byte 1 of SetMotion (0x0B).

    ``F*`` modes carry a float32 (rad, rad/s, A), ``I*`` modes an int32 (encoder ticks,
    ticks/s, current digits). Step modes add a uint16 time in ms. ``*_ACK`` modes are
    answered with the extended acknowledge (actual position, short state, dio) instead of
    ``[0x0B, mode, 0x64]``. FCOSLOOP / FRAMPLOOP are only in the Bosch sources (f32 + u16
    period) and unverified elsewhere.
    """

    FRAMP = 0x04
    FSTEP = 0x06
    FVEL = 0x07
    FCUR = 0x08
    IRAMP = 0x09
    ISTEP = 0x0B
    IVEL = 0x0C
    ICUR = 0x0D
    FRAMP_ACK = 0x0E
    FSTEP_ACK = 0x10
    FVEL_ACK = 0x11
    FCUR_ACK = 0x12
    IRAMP_ACK = 0x13
    ISTEP_ACK = 0x15
    IVEL_ACK = 0x16
    ICUR_ACK = 0x17
    FCOSLOOP = 0x18
    FRAMPLOOP = 0x19

    @property
    def is_extended_ack(self) -> bool:
        """Answered with position, short state and dio (``MotionExtAck``)."""
        return self in _EXT_ACK_MODES

    @property
    def is_float(self) -> bool:
        """The value is a float32; otherwise an int32 (ticks / digits)."""
        return self not in _INT_MODES

    @property
    def has_time(self) -> bool:
        """A uint16 time / period in ms follows the value (step and loop modes)."""
        return self in _TIMED_MODES

    def with_ext_ack(self) -> MotionMode:
        """The ``*_ACK`` twin of this mode (itself if it already is one)."""
        return _TO_EXT.get(self, self)

    def without_ext_ack(self) -> MotionMode:
        """The plain twin of a ``*_ACK`` mode (itself otherwise)."""
        return _FROM_EXT.get(self, self)


_M = MotionMode
_EXT_ACK_MODES = frozenset({_M.FRAMP_ACK, _M.FSTEP_ACK, _M.FVEL_ACK, _M.FCUR_ACK,
                            _M.IRAMP_ACK, _M.ISTEP_ACK, _M.IVEL_ACK, _M.ICUR_ACK})
_INT_MODES = frozenset({_M.IRAMP, _M.ISTEP, _M.IVEL, _M.ICUR,
                        _M.IRAMP_ACK, _M.ISTEP_ACK, _M.IVEL_ACK, _M.ICUR_ACK})
_TIMED_MODES = frozenset({_M.FSTEP, _M.ISTEP, _M.FSTEP_ACK, _M.ISTEP_ACK,
                          _M.FCOSLOOP, _M.FRAMPLOOP})
_TO_EXT = {_M.FRAMP: _M.FRAMP_ACK, _M.FSTEP: _M.FSTEP_ACK, _M.FVEL: _M.FVEL_ACK,
           _M.FCUR: _M.FCUR_ACK, _M.IRAMP: _M.IRAMP_ACK, _M.ISTEP: _M.ISTEP_ACK,
           _M.IVEL: _M.IVEL_ACK, _M.ICUR: _M.ICUR_ACK}
_FROM_EXT = {ext: plain for plain, ext in _TO_EXT.items()}


class StateFlag(_Describe, IntFlag):
    """The 32-bit module state word (parameter 0x27 CubeState), section D.1."""

    ERROR = 0x00000001
    HOME_OK = 0x00000002
    HALTED = 0x00000004
    POWERFAULT = 0x00000008
    TOW_ERROR = 0x00000010
    COMM_ERROR = 0x00000020
    SWR = 0x00000040
    SW1 = 0x00000080
    SW2 = 0x00000100
    BRAKEACTIVE = 0x00000200
    CURLIMIT = 0x00000400
    MOTION = 0x00000800
    RAMP_ACC = 0x00001000
    RAMP_STEADY = 0x00002000
    RAMP_DEC = 0x00004000
    RAMP_END = 0x00008000
    INPROGRESS = 0x00010000
    FULLBUFFER = 0x00020000
    POW_VOLT_ERR = 0x00040000
    POW_FET_TEMP = 0x00080000
    POW_WDG_TEMP = 0x00100000  # motor winding temperature, not the watchdog
    POW_SHORTCUR = 0x00200000
    POW_HALLERR = 0x00400000
    POW_INTEGRALERR = 0x00800000
    CPU_OVERLOAD = 0x01000000
    BEYOND_HARD = 0x02000000
    BEYOND_SOFT = 0x04000000
    POW_SETUP_ERR = 0x08000000
    LOGIC_VOLT = 0x08000000  # m5api/Bosch name of the same bit

    #: Every bit that means "the module stopped or refuses motion".
    FAULTS = (ERROR | HALTED | POWERFAULT | TOW_ERROR | COMM_ERROR | POW_VOLT_ERR
              | POW_FET_TEMP | POW_WDG_TEMP | POW_SHORTCUR | POW_HALLERR | POW_INTEGRALERR
              | CPU_OVERLOAD | BEYOND_HARD | BEYOND_SOFT | POW_SETUP_ERR)

    @property
    def faults(self) -> StateFlag:
        """Only the fault bits of this state."""
        return self & StateFlag.FAULTS

    @property
    def is_fault(self) -> bool:
        return bool(self & StateFlag.FAULTS)


class ShortState(_Describe, IntFlag):
    """The short state byte of extended acks and FPosStateDio (table in B.3).

    ``NOT_OK`` is ERROR **or** not HOME_OK **or** HALTED; ``describe()`` of 0 is ``"OK"``.
    """

    NOT_OK = 0x01
    SWR = 0x02
    SW1 = 0x04
    SW2 = 0x08
    MOTION = 0x10
    RAMP_END = 0x20
    INPROGRESS = 0x40
    FULLBUFFER = 0x80

    def describe(self) -> str:
        return "OK" if self == 0 else super().describe()

    # The joint-level view a driver reports every cycle (seqrun.drivers.base.CycleState);
    # plain int tests: they run for every module in every control cycle.
    @property
    def refuses_motion(self) -> bool:
        return bool(int(self) & 0x01)   # NOT_OK

    @property
    def moving(self) -> bool:
        return bool(int(self) & 0x10)   # MOTION

    def to_state_flags(self) -> StateFlag:
        """Expand to the state word like m5api (``NOT_OK`` becomes ``ERROR``)."""
        result = StateFlag(0)
        for bit, flag in _SHORT_TO_STATE:
            if self & bit:
                result |= flag
        return result


_SHORT_TO_STATE = (
    (ShortState.NOT_OK, StateFlag.ERROR),
    (ShortState.SWR, StateFlag.SWR),
    (ShortState.SW1, StateFlag.SW1),
    (ShortState.SW2, StateFlag.SW2),
    (ShortState.MOTION, StateFlag.MOTION),
    (ShortState.RAMP_END, StateFlag.RAMP_END),
    (ShortState.INPROGRESS, StateFlag.INPROGRESS),
    (ShortState.FULLBUFFER, StateFlag.FULLBUFFER),
)


class ConfigFlag(_Describe, IntFlag):
    """The config word (parameter 0x39 Config, default 0x1B DefConfig), section D.3.

    Bits 0-2 are the feedback type on firmware 25xx and have no names here.
    """

    BRAKE_PRESENT = 0x00000008
    BRAKE_AT_POWERON = 0x00000010
    SWR_WITH_ENCODERZERO = 0x00000020
    SWR_AT_FALLING_EDGE = 0x00000040
    CHANGE_SWR_TO_LIMIT = 0x00000080
    SWR_ENABLED = 0x00000100
    SWR_LOW_ACTIVE = 0x00000200
    SWR_USE_EXTERNAL = 0x00000400
    SW1_ENABLED = 0x00000800
    SW1_LOW_ACTIVE = 0x00001000
    SW1_EQ_POSLIMIT = 0x00002000
    SW2_ENABLED = 0x00004000
    SW2_LOW_ACTIVE = 0x00008000
    SW2_EQ_POSLIMIT = 0x00010000
    LINEAR = 0x00020000
    OPENBRAKE_ON_SW2 = 0x00040000
    ALLOW_FULL_CUR = 0x00080000
    M3_COMPATIBLE = 0x00100000
    LINEAR_SCREW = 0x00200000
    DISABLE_ON_HALT = 0x00800000
    WATCHDOG_ENABLE = 0x01000000
    ZERO_MOVE_AFTER_HOK = 0x02000000
    DISABLE_ACK = 0x04000000
    SYNC_MOTION = 0x08000000
    SYNC_TRANSMIT = 0x10000000
    CAN_RS232_COMM = 0x40000000
    PROFI_RS485_COMM = 0x80000000


class SetupFlag(_Describe, IntFlag):
    """The setup word (parameter 0x58 Setup); ABSOLUTE or RESOLVER feedback means PRL."""

    ENCODER = 0x0001
    RESOLVER = 0x0002
    ABSOLUTE = 0x0004
    CAN = 0x0200
    USE_M3ID = 0x0800
    USE_M4ID = 0x1000
    CANOPEN = 0x2000
    INVERT_MOTORDIR = 0x4000


class BaudRate(IntEnum):
    """Baud-rate ids for SetBaudAll and DefPrimBaud."""

    BAUD_125K = 0
    BAUD_250K = 1
    BAUD_500K = 2
    BAUD_1M = 3

    @property
    def bits_per_second(self) -> int:
        return (125_000, 250_000, 500_000, 1_000_000)[self.value]

    @classmethod
    def from_bits_per_second(cls, bitrate: int) -> BaudRate:
        for member in cls:
            if member.bits_per_second == bitrate:
                return member
        raise ValueError(f"unsupported PowerCube bitrate {bitrate} (125k, 250k, 500k or 1M)")
