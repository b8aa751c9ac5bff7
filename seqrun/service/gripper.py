"""The gripper from a face: Grip and Release as one-step sequences, and its state.

A Grip or a Release from the console is a one-step sequence (``grip``/``release``) run by
the executor like any console move: validated against the arm file first (a force above
the gripper's limit, a width beyond its stroke: refused, nothing sent), one activity at a
time, behind the control desk of the face. The state is read from the gripper module when
the session is idle, else it is the last one a step reported.
"""

from __future__ import annotations

import json
import threading
from typing import TYPE_CHECKING, Any

from seqrun.errors import Refused

if TYPE_CHECKING:
    from seqrun.service.activities import Activity

__all__ = ["GripperControl"]


class GripperControl:
    """``session.gripper``: grip, release, state."""

    def __init__(self, session: Any) -> None:  # the ArmSession it is part of
        self._session = session
        self._lock = threading.Lock()
        self._last: dict[str, Any] | None = None

    def _spec(self, what: str):
        spec = self._session.arm.gripper
        if spec is None:
            raise Refused(f"{what}: the arm file has no gripper")
        return spec

    def grip(self, part_width_mm: float, force_n: float, *,
             by: str | None = None) -> Activity:
        """Close on a part of ``part_width_mm`` with ``force_n`` (non-blocking)."""
        from seqrun.service.motion import finite

        self._spec("grip")
        params = {"part_width_mm": finite(part_width_mm, "grip: part width"),
                  "force_n": finite(force_n, "grip: force"), "label": "Grip (session)"}
        return self._start("grip", params, by)

    def release(self, width_mm: float, *, by: str | None = None) -> Activity:
        """Open the jaws to ``width_mm`` (non-blocking)."""
        from seqrun.service.motion import finite

        self._spec("release")
        params = {"width_mm": finite(width_mm, "release: width"), "label": "Release (session)"}
        return self._start("release", params, by)

    def _start(self, kind: str, params: dict[str, Any], by: str | None) -> Activity:
        motion = self._session.motion
        loaded = motion.validated_step(kind, f"{kind}: {json.dumps(params)}", kind)
        return motion.start_steps(kind, loaded, params, by)

    def state(self) -> dict[str, Any] | None:
        """The gripper now (idle: read from the module), else the last reading; None for an
        arm without a gripper."""
        s = self._session
        spec = s.arm.gripper
        if spec is None:
            return None
        bus = s.activities.bus
        if bus.acquire(blocking=False):
            try:
                if s.activities.current is None and not s.driver.closed:
                    from seqrun.drivers.base import GripperDriver

                    if not isinstance(s.driver, GripperDriver):
                        raise Refused("the arm's driver does not drive a gripper")
                    reading = s.driver.gripper_read()
                    with self._lock:
                        self._last = {"name": spec.name, "width_mm": round(reading.width_mm, 2),
                                      "holding": reading.at_current_limit
                                      and abs(reading.velocity_mm_s) < 0.5,
                                      "moving": reading.moving, "faulted": reading.faulted,
                                      "homed": reading.homed,
                                      "state": reading.text, "module": spec.module,
                                      "stroke_mm": spec.stroke_mm,
                                      "max_force_n": spec.max_force_n}
            except Exception as exc:  # noqa: BLE001 - a read never raises: state goes stale
                with self._lock:
                    self._last = {"name": spec.name, "error": str(exc), "module": spec.module,
                                  "stroke_mm": spec.stroke_mm, "max_force_n": spec.max_force_n}
            finally:
                bus.release()
        with self._lock:
            return dict(self._last) if self._last is not None else None
