"""The arm outside a run, for the short commands (``seqrun status``, ``halt``, ``reset``,
``pose save``, the zero-reference check at a run's start): open the bus with a PowerCube
client, read the whole arm's status, check Home, broadcast Halt/Reset and confirm it.

The faces (cli/, console/) call these and never build PowerCube requests themselves
(``tests/test_architecture.py`` holds them to it). Everything heavy is imported inside the
functions: the CLI's start-up stays light.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING, Any, cast

if TYPE_CHECKING:
    from seqrun.arm.description import ArmDescription
    from seqrun.service.connection import Connection
    from seqrun.drivers.base import CommandConfirmation, JointState

__all__ = ["broadcast_and_confirm", "modules_homed", "open_arm", "poll_joints", "read_status"]


def open_arm(arm: ArmDescription, *, interface: str | None, channel: str | None,
             bitrate: int | None, bus_kwargs: Sequence[str] = (), sim: bool = False,
             faults: Sequence[str] = (), response_timeout_ms: float | None = None,
             claim: bool = True, transient: bool = True) -> tuple[Connection, Any]:
    """Open the bus and a PowerCube client on it: ``(connection, client)``. The bus is
    claimed (for a moment with ``transient``): a run's claim refuses it, naming the run."""
    from seqrun.service.connection import (open_connection, parse_bus_kwargs, parse_faults,
                                   response_timeout_s)
    from seqrun.powercube.client import PowerCubeClient

    timeout = response_timeout_s(arm, response_timeout_ms)  # (checked before connecting)
    connection = open_connection(interface=interface, channel=channel, bitrate=bitrate,
                                 bus_kwargs=parse_bus_kwargs(list(bus_kwargs)), force_sim=sim,
                                 faults=parse_faults(list(faults)),
                                 default_bitrate=arm.can.bitrate, claim=claim,
                                 transient=transient)
    client = PowerCubeClient(connection.bus, connection.clock, response_timeout=timeout)
    return connection, client


def read_status(client, arm, previous: dict | None = None, *,
                tolerate_loss: bool = False) -> dict:
    """Joints (user degrees), velocities, state words and the end-effector pose.

    ``tolerate_loss`` (``--watch``): a request without an answer does not raise; its
    joint keeps the values of ``previous`` (the last refresh) marked ``"stale": true``,
    or None when there is no previous value.
    """
    import numpy as np

    from seqrun.arm.kinematics import Chain, fk, rpy_from_matrix
    from seqrun.powercube.codec import GetParam
    from seqrun.powercube.protocol import ParamId, StateFlag

    requests = [GetParam(j.module, p) for j in arm.joints
                for p in (ParamId.ACT_POS, ParamId.ACT_VEL, ParamId.CUBE_STATE)]
    acks = (client.transact_partial(requests) if tolerate_loss
            else client.transact(requests))
    before = {j["joint"]: j for j in (previous or {}).get("joints", [])}
    joints = []
    for k, joint in enumerate(arm.joints):
        answers = acks[3 * k:3 * k + 3]
        if any(a is None for a in answers):
            old = before.get(joint.name)
            joints.append({**(old or {"joint": joint.name, "module": joint.module,
                                      "position_deg": None, "velocity_deg_s": None,
                                      "state": None, "fault": False}), "stale": True})
            continue
        pos, vel, state = (a.value for a in answers)
        joints.append({"joint": joint.name, "module": joint.module,
                       "position_deg": round(joint.to_user_deg(float(pos)), 4),
                       "velocity_deg_s": round(math.degrees(float(vel)), 4),
                       "state": StateFlag(state).describe(),
                       "fault": bool(StateFlag(state) & StateFlag.FAULTS),
                       "stale": False})
    if any(j["position_deg"] is None for j in joints):
        return {"joints": joints, "end_effector": None}
    q = np.radians([j["position_deg"] for j in joints])
    T = fk(Chain.from_arm(arm), q)
    return {"joints": joints,
            "end_effector": {"position_mm": [round(float(x), 3) for x in T[:3, 3]],
                             "rpy_deg": [round(float(x), 3)
                                         for x in np.degrees(rpy_from_matrix(T[:3, :3]))]}}


def poll_joints(client, arm) -> tuple[list[float], list[float], dict[int, JointState]]:
    """One pipelined read of ActPos, ActVel and CubeState of every module: positions (user
    degrees), velocities (deg/s) and each module's decoded state, by module id. Raises
    :class:`~seqrun.errors.BusError` naming the modules that did not answer."""
    from seqrun.drivers.powercube import joint_state
    from seqrun.errors import BusError
    from seqrun.powercube.codec import GetParam
    from seqrun.powercube.protocol import ParamId

    requests = [GetParam(j.module, p) for j in arm.joints
                for p in (ParamId.ACT_POS, ParamId.ACT_VEL, ParamId.CUBE_STATE)]
    acks = client.transact_partial(requests)
    if any(a is None for a in acks):
        missing = sorted({r.module for r, a in zip(requests, acks) if a is None})
        raise BusError(f"no answer from module(s) {', '.join(map(str, missing))}")
    joints, velocities, states = [], [], {}
    for k, joint in enumerate(arm.joints):
        pos, vel, state = (a.value for a in acks[3 * k:3 * k + 3])
        joints.append(round(joint.to_user_deg(float(pos)), 4) + 0.0)
        velocities.append(round(math.degrees(float(vel)), 4) + 0.0)
        states[joint.module] = joint_state(int(state))
    return joints, velocities, states


def modules_homed(connection, arm) -> bool:
    """True when every module reports HOME_OK (no power-on since the last start-up)."""
    from seqrun.errors import ModuleTimeoutError
    from seqrun.powercube.client import PowerCubeClient
    from seqrun.powercube.codec import GetParam, GetParamAck
    from seqrun.powercube.protocol import ParamId, StateFlag

    client = PowerCubeClient(connection.bus, connection.clock,
                             response_timeout=arm.can.response_timeout_s)
    try:
        for attempt in range(3):  # a read is idempotent: a lost answer is asked again
            try:
                acks = client.transact([GetParam(m, ParamId.CUBE_STATE)
                                        for m in arm.module_ids])
                break
            except ModuleTimeoutError:
                if attempt == 2:
                    raise
    finally:
        client.close()
    return all(StateFlag(cast(GetParamAck, a).value) & StateFlag.HOME_OK for a in acks)


def watch_foreign_frames(client: Any, on_foreign: Any, *, echoes_own: bool = False) -> None:
    """Call ``on_foreign(frame)`` for every request frame ``client`` receives that this
    process did not send (another master on the bus)."""
    from seqrun.drivers.powercube.foreign import ForeignFrameWatch

    client.add_frame_listener(ForeignFrameWatch(on_foreign, echoes_own=echoes_own))


def broadcast_and_confirm(client: Any, what: str, modules: Iterable[int]
                          ) -> CommandConfirmation:
    """Broadcast ``what`` ("halt" or "reset") and confirm it on every module of
    ``modules`` by reading their states back (:func:`seqrun.drivers.powercube.command_and_confirm`)."""
    from seqrun.drivers.powercube import command_and_confirm
    from seqrun.powercube.protocol import CommandId

    return command_and_confirm(client, CommandId[what.upper()], modules)
