"""The gripper module in PowerCube terms: mm <-> module units, its requests and reading.

A PowerCube gripper (Schunk PG 70) is a linear module: position, velocity and acceleration
in metres (m, m/s, m/s²) of opening width [I: the linear modules' SI unit]; its grip force is
its current limit MaxCur (A). Above the driver everything is mm and N
(:class:`~seqrun.arm.gripper.GripperSpec`); this is the one place that converts.
"""

from __future__ import annotations

from seqrun.arm.gripper import GripperSpec
from seqrun.arm.joint_values import GripperReading
from seqrun.powercube.codec import GetParam, Request, SetMotion, SetParam
from seqrun.powercube.protocol import MotionMode, ParamId, StateFlag

__all__ = ["MM_PER_UNIT", "move_requests", "read_requests", "reading"]

#: Millimetres per module unit (metres).
MM_PER_UNIT = 1000.0
#: A current limit reads back within this (A): the module stores float32.
CURRENT_TOLERANCE_A = 1e-3


def module_units(mm: float) -> float:
    return mm / MM_PER_UNIT


def millimetres(units: float) -> float:
    return units * MM_PER_UNIT


def move_requests(spec: GripperSpec, width_mm: float, speed_mm_s: float) -> list[Request]:
    """TargetVel, TargetAcc, then FRAMP_ACK to ``width_mm`` (clamped to the stroke)."""
    width = min(max(width_mm, 0.0), spec.stroke_mm)
    speed = min(speed_mm_s, spec.max_velocity_mm_s)
    return [SetParam(spec.module, ParamId.TARGET_VEL, module_units(speed)),
            SetParam(spec.module, ParamId.TARGET_ACC, module_units(spec.max_acceleration_mm_s2)),
            SetMotion(spec.module, MotionMode.FRAMP_ACK, module_units(width))]


def read_requests(spec: GripperSpec) -> list[Request]:
    return [GetParam(spec.module, ParamId.ACT_POS), GetParam(spec.module, ParamId.ACT_VEL),
            GetParam(spec.module, ParamId.CUBE_STATE)]


def reading(position: float, velocity: float, state: int) -> GripperReading:
    flags = StateFlag(state)
    return GripperReading(
        width_mm=millimetres(position), velocity_mm_s=millimetres(velocity),
        moving=bool(flags & StateFlag.MOTION),
        at_current_limit=bool(flags & StateFlag.CURLIMIT),
        faulted=flags.is_fault, homed=bool(flags & StateFlag.HOME_OK),
        text=flags.describe())
