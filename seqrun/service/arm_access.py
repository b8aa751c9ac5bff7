"""The arm outside a run, for the short commands (``seqrun status``, ``halt``, ``reset``,
``pose save``, the zero-reference check at a run's start): read the whole arm's status,
check Home, broadcast Halt/Reset and confirm it. (The bus and the driver are opened by
the arm context: :meth:`seqrun.service.arm_context.ArmContext.open_arm`.)

The faces (cli/, console/) call these and hold what they return; they never see a
protocol (``tests/test_architecture.py`` holds them to it). Everything heavy is imported
inside the functions: the CLI's start-up stays light.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from seqrun.arm.description import ArmDescription
    from seqrun.drivers.base import ArmDriver, ArmIdentity, CommandConfirmation
    from seqrun.service.connection import Connection

__all__ = ["home_and_confirm", "identity_and_session_mark",
           "leave_session_mark", "modules_homed", "modules_of",
           "read_joints", "read_status", "status_rows"]




def status_rows(arm: ArmDescription, poll, previous: dict | None = None) -> list[dict]:
    """A driver's poll as the rows ``seqrun status`` prints (user degrees, rounded); a
    joint without an answer keeps the row of ``previous`` (the last refresh), marked
    ``"stale": true``, or has None values."""
    before = {j["joint"]: j for j in (previous or {}).get("joints", [])}
    rows = []
    for k, joint in enumerate(arm.joints):
        state = poll.states[joint.module]
        if state is None:
            old = before.get(joint.name)
            rows.append({**(old or {"joint": joint.name, "module": joint.module,
                                    "position_deg": None, "velocity_deg_s": None,
                                    "state": None, "fault": False}), "stale": True})
            continue
        rows.append({"joint": joint.name, "module": joint.module,
                     "position_deg": round(poll.positions_deg[k], 4),
                     "velocity_deg_s": round(poll.velocities_deg_s[k], 4),
                     "state": state.text, "fault": state.faulted, "stale": False})
    return rows


def read_status(driver: ArmDriver, arm: ArmDescription, previous: dict | None = None, *,
                tolerate_loss: bool = False) -> dict:
    """Joints (user degrees), velocities, state words and the end-effector pose.

    ``tolerate_loss`` (``--watch``): a request without an answer does not raise; its
    joint keeps the values of ``previous`` (the last refresh) marked ``"stale": true``,
    or None when there is no previous value.
    """
    from seqrun.service.kinematics import end_effector

    joints = status_rows(arm, driver.poll(tolerate_loss=tolerate_loss), previous)
    if any(j["position_deg"] is None for j in joints):
        return {"joints": joints, "end_effector": None}
    return {"joints": joints,
            "end_effector": end_effector(arm, [j["position_deg"] for j in joints])}


def read_joints(driver: ArmDriver) -> tuple[list[float], list[float], dict[int, Any]]:
    """One reading of every joint: positions (user degrees), velocities (deg/s) and each
    module's decoded state, by module id. Raises :class:`~seqrun.errors.BusError` naming
    the modules that did not answer."""
    from seqrun.errors import BusError

    poll = driver.poll(tolerate_loss=True)
    if not poll.complete:
        raise BusError(f"no answer from module(s) {', '.join(map(str, poll.missing()))}")
    joints = [round(x, 4) + 0.0 for x in poll.positions_deg if x is not None]  # (no -0.0)
    velocities = [round(v, 4) + 0.0 for v in poll.velocities_deg_s if v is not None]
    return joints, velocities, dict(poll.states)


def modules_homed(connection: Connection, arm: ArmDescription) -> bool:
    """True when every module reports homed (no power-on since the last start-up)."""
    from seqrun.drivers.registry import open_driver

    driver = open_driver(arm, connection)
    try:
        return driver.homed()
    finally:
        driver.close()


def identity_and_session_mark(connection: Connection,
                              arm: ArmDescription) -> tuple[ArmIdentity, int | None]:
    """Which physical arm is on the bus (its modules' serial numbers) and the
    power-session mark its modules hold (None: none since they powered on); reads only."""
    from seqrun.drivers.registry import open_driver

    driver = open_driver(arm, connection)
    try:
        identity, mark = driver.identity(), driver.session_mark()
    finally:
        driver.close()
    if connection.claim is not None and not connection.is_simulator:
        # one controller per arm, over whichever bus reaches it (bus_claim.py)
        connection.claim.claim_arm(identity.key, identity.describe())
    return identity, mark


def leave_session_mark(connection: Connection, arm: ArmDescription, mark: int) -> bool:
    """Leave the power-session ``mark`` in the arm's modules; False when they do not keep
    it (read back)."""
    from seqrun.drivers.registry import open_driver

    driver = open_driver(arm, connection)
    try:
        return driver.write_session_mark(mark)
    finally:
        driver.close()


def broadcast_and_confirm(driver: ArmDriver, what: str) -> CommandConfirmation:
    """Broadcast ``what`` ("halt" or "reset") and confirm it on every module by reading
    their states back."""
    return driver.confirm(what)  # type: ignore[arg-type]


def modules_of(arm: ArmDescription, joint_names: list[str] | None) -> list[int] | None:
    """The module ids of the joints named (None: every module of the arm). An unknown or
    repeated name is a :class:`~seqrun.errors.UserInputError` naming the arm's joints."""
    from seqrun.errors import UserInputError

    if joint_names is None:
        return None
    known = {j.name: j.module for j in arm.joints}
    if not joint_names:
        raise UserInputError(f"--joints names no joint (the arm's: {', '.join(known)})")
    unknown = [n for n in joint_names if n not in known]
    if unknown:
        raise UserInputError(f"unknown joint(s) {', '.join(unknown)}: arm '{arm.name}' has "
                             f"{', '.join(known)}")
    return list(dict.fromkeys(known[n] for n in joint_names))


def home_and_confirm(driver: ArmDriver,
                     modules: list[int] | None = None) -> CommandConfirmation:
    """Home ``modules`` (None: the whole arm) and confirm it by reading every module back
    (HOME_OK, at rest); a halted or faulted module is not homed (its error says so)."""
    return driver.confirm("home", modules)
