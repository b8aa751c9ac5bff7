"""The thesis' way of driving the LWA 3, re-created as a client of the simulated arm.

A baseline for ``bench_thesis.py`` and ``bench_telemetry.py``, not a model to copy. Source:
/work/shared/seeds/thesis-schunk-lwa3-control.txt, chapter 5 and appendices A and B.

What the thesis shows, and what is reproduced here frame for frame:

- ``launch.launcher(CAN_msg)`` (5.2) sends ONE message, then "after a pause of one second"
  reads the message received on the bus (its acknowledge) and prints it. Every message of
  the thesis goes through it, so every CAN message is followed by a 1-second wait, and
  nothing is ever pipelined. Here: ``send``, ``clock.sleep(1.0)``, ``recv(timeout=0)``.
- ``Dugtrio.read()`` (appendix B, lines 29-39): ``GetExtended ActPos`` (0x0C<m> 0A 3C) for
  modules 1, 2, 4, 5, 6, 7 (module 3 is skipped), one launcher call each: 6 s per read.
  ``Dugtrio.__init__`` calls it once at program start; ``home()``, ``totem()``,
  ``opsafe()`` call it after their commands (lines 133-165).
- "Arm" (``Multiple.Arm``, 5.3 and appendix A): Reset to all joints (broadcast 0x100), then
  MinPos and MaxPos of each module (SetExtended 0x45/0x46). Appendix A: Arm first, then
  Home (broadcast 0x100).
- Motion (5.1): per joint, "with two consecutive messages", SetExtended TargetVel (0x4F),
  then SetMotion FRAMP_MODE (0x04) to the position, joint after joint.
- Totem from Park (5.3): "these values have been used as parameter for a FRAMP_POS motion
  command to move joints 2, 4 and 6" (table 5.1: joints 1, 3, 5, 7 need no offset).
- Op-safe (table 5.2, relative to Totem): [70, 30, 0, 70, 20, 50, 0] deg.

Not in the thesis' listings (``Multiple.py`` and ``JointControl.py`` are not printed), so
assumed and stated here:

- the velocity: TargetVel 0.77 rad/s for every joint, the only velocity the thesis gives
  (its worked example of a TargetVel message, 4.3.1); TargetAcc is never written;
- Op-safe moves the joints whose table 5.2 value differs from Totem's (1, 2, 4, 5, 6), as
  Totem moves only the joints with an offset (2, 4, 6);
- the limits written by "Arm" are the arm file's (``arms/lwa3.yaml``), in module
  coordinates (``module = user + offset``: the thesis adds the offsets "to make them fall
  into line with the positions read by the arm"), for all seven modules ("for each joint");
  the same values seqrun's ``set_limits`` step writes;
- the launcher's read after the pause takes whatever one frame has arrived (none for a
  broadcast) instead of blocking.

No operator typing time is counted: the session runs its commands back to back.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import can

from seqrun.arm.description import ArmDescription
from seqrun.clock import Clock
from seqrun.errors import CodecError
from seqrun.powercube.codec import (BroadcastRequest, GetParam, SetMotion, SetParam,
                                    decode_ack, encode)
from seqrun.powercube.protocol import CommandId, MotionMode, ParamId
from seqrun.drivers.powercube.units import to_module_rad

#: ``launch.launcher``: "After a pause of one second ..." (thesis 5.2).
LAUNCHER_PAUSE_S = 1.0
#: The thesis' TargetVel (4.3.1: "the velocity of module 2 has to be set to 0.77").
THESIS_VELOCITY_RAD_S = 0.77
#: Modules ``Dugtrio.read()`` asks for ActPos (``if i != 3``).
READ_MODULES = (1, 2, 4, 5, 6, 7)
#: Joints (1-based) moved by the thesis' Totem command from Park (5.3).
TOTEM_JOINTS = (2, 4, 6)
#: Op-safe, user degrees (table 5.2).
OPSAFE_DEG = (70.0, 30.0, 0.0, 70.0, 20.0, 50.0, 0.0)
TOTEM_DEG = (0.0,) * 7


@dataclass
class Launch:
    """One ``launcher`` call: what was sent, when, and the frame read after the pause."""

    t: float
    request: object
    reply: object | None


@dataclass
class ThesisSession:
    """The thesis' command-line session (``dugtrio_arm_model.py``) over ``bus``.

    ``pause_s`` is the launcher's pause (1 s); with ``pause_s=None`` the launcher instead
    waits for the acknowledge (up to ``ack_timeout_s``) and sends the next message at once:
    the thesis' request pattern without the waits (``bench_telemetry``).
    """

    bus: can.BusABC
    clock: Clock
    arm: ArmDescription
    pause_s: float | None = LAUNCHER_PAUSE_S
    velocity_rad_s: float = THESIS_VELOCITY_RAD_S
    ack_timeout_s: float = 0.05
    log: list[Launch] = field(default_factory=list)
    joints: list[float] = field(default_factory=list)

    # -- launch.launcher -----------------------------------------------------------------
    def launcher(self, request) -> object | None:
        can_id, data = encode(request)
        t = self.clock.now()
        self.bus.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))
        if self.pause_s is not None:
            self.clock.sleep(self.pause_s)
            msg = self.bus.recv(timeout=0.0)
        elif isinstance(request, BroadcastRequest):
            msg = None  # never acknowledged
        else:
            msg = self.bus.recv(timeout=self.ack_timeout_s)
        reply = None
        if msg is not None:
            try:
                reply = decode_ack(msg.arbitration_id, bytes(msg.data))
            except CodecError:  # the thesis printed whatever came; here it is dropped
                reply = None
        self.log.append(Launch(t, request, reply))
        return reply

    # -- Dugtrio ---------------------------------------------------------------------------
    def read(self) -> list[float]:
        """``Dugtrio.read()``: ActPos of modules 1, 2, 4-7, joint 3 taken as 0 (radians,
        module coordinates)."""
        position = []
        for module in READ_MODULES:
            reply = self.launcher(GetParam(module, ParamId.ACT_POS))
            position.append(float(reply.value) if reply is not None else math.nan)
        position.insert(2, 0.0)
        self.joints = position
        return position

    def start(self) -> None:
        """``python dugtrio_arm_model.py``: ``Dugtrio.__init__`` reads the arm once."""
        self.read()

    def arm_command(self) -> None:
        """``arm`` -> ``Multiple.Arm()``: Reset (broadcast), MinPos/MaxPos per module."""
        self.launcher(BroadcastRequest(CommandId.RESET))
        for joint in self.arm.joints:
            lo, hi = joint.limits_deg
            self.launcher(SetParam(joint.module, ParamId.MIN_POS, to_module_rad(joint, lo)))
            self.launcher(SetParam(joint.module, ParamId.MAX_POS, to_module_rad(joint, hi)))

    def home(self) -> None:
        """``home`` -> ``GeneralCommands.Home()`` (broadcast), then the listing's
        ``while [-eps]*7 < self.joints < [eps]*7: self.read(); break``."""
        self.launcher(BroadcastRequest(CommandId.HOME))
        eps = 0.1
        if [0 - eps] * 7 < self.joints < [0 + eps] * 7:
            self.read()

    def move_joints(self, joints: tuple[int, ...], user_deg: tuple[float, ...]) -> None:
        """Per joint, one after the other: TargetVel, then FRAMP to the position."""
        for number in joints:
            joint = self.arm.joints[number - 1]
            self.launcher(SetParam(joint.module, ParamId.TARGET_VEL, self.velocity_rad_s))
            self.launcher(SetMotion(joint.module, MotionMode.FRAMP,
                                    to_module_rad(joint, user_deg[number - 1])))

    def totem(self) -> None:
        """``totem`` -> ``Multiple.Totem()`` (joints 2, 4, 6), then ``self.read()``."""
        self.move_joints(TOTEM_JOINTS, TOTEM_DEG)
        self.read()

    def opsafe(self) -> None:
        """``opsafe`` -> ``Multiple.Opsafe()`` (joints off Totem in table 5.2), then
        ``self.read()``."""
        moved = tuple(i + 1 for i, v in enumerate(OPSAFE_DEG) if v != TOTEM_DEG[i])
        self.move_joints(moved, OPSAFE_DEG)
        self.read()

    def park_to_opsafe(self) -> None:
        """The whole session: start, arm, home, totem, opsafe."""
        self.start()
        self.arm_command()
        self.home()
        self.totem()
        self.opsafe()


def timed(fn, clock: Clock) -> tuple[float, float]:
    """(seconds on ``clock``, wall seconds) taken by ``fn()``."""
    c0, w0 = clock.now(), time.perf_counter()
    fn()
    return clock.now() - c0, time.perf_counter() - w0
