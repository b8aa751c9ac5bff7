"""What the subscribers of a run get beyond the event log: each reading's windowed
velocities and each joint's flag names and fault, as the driver decoded them.

A ``measurement`` event gets these fields; a ``setpoint`` (one per streamed cycle, the log
holds it) is handed on to the subscribers as a ``measurement`` too, with them. Computed
only while someone subscribes.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from seqrun.drivers.telemetry import VelocityWindow, joint_flags
from seqrun.arm.tracking import velocity_window

if TYPE_CHECKING:
    from seqrun.execution.run import Run


class SubscriberFields:
    """The derived fields of one run's readings (module docstring)."""

    def __init__(self, run: Run) -> None:
        self._run = run
        self._velocity = VelocityWindow(velocity_window(run.cycle))

    def derive(self, type_: str, data: dict) -> dict[str, dict]:
        """``{"measurement": fields}`` for a measurement, ``{"cycle": data,
        "cycle_derived": fields}`` for a setpoint, ``{}`` for anything else."""
        if type_ == "measurement":
            joints = data.get("joints_deg")
        elif type_ == "setpoint":
            joints = data.get("measured_deg")
        else:
            return {}
        short = data.get("state") or []
        if joints is None:
            return {}
        run = self._run
        # the reading's time: when the joints answered (a stalled host stamps late)
        self._velocity.add(run.last.at if run.last is not None else run.clock.now(), joints)
        # The reading this event reports (read_arm and refresh_measurement set it first),
        # decoded by the driver; its full states only for a measurement that shows them.
        m = run.last
        flags, fault = joint_flags(
            run.arm.joint_names, run.modules, m.short_state if m is not None else {},
            m.state_words if m is not None and type_ == "measurement" else None)
        extra: dict[str, Any] = {"velocities_deg_s": self._velocity.velocity(),
                                 "flags": flags, "fault": fault,
                                 "read_clock_s": m.at if m is not None else None}
        if type_ == "measurement":
            return {"measurement": {**extra, "source": "step" if "after" in data
                                    else "monitor"}}
        cycle = {"joints_deg": joints, "state": short}
        if "step" in data:
            cycle["step"] = data["step"]
        return {"cycle": cycle, "cycle_derived": {**extra, "source": "cycle"}}
