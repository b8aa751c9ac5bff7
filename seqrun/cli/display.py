"""What the operator sees during a run: a rich live view on a terminal, plain lines otherwise.

Both are executor listeners; they only read events and the executor's last measurement,
so a slow terminal can never hold up the control loop (rich refreshes from its own thread).
"""

from __future__ import annotations

import threading
from typing import Any

import numpy as np
from rich.console import Console, Group
from rich.live import Live
from rich.panel import Panel
from rich.progress_bar import ProgressBar
from rich.table import Table
from rich.text import Text

from seqrun import kinematics


def _fmt_duration(x: float | None) -> str:
    return "-" if x is None else f"{x:.2f} s"


class PlainDisplay:
    """One line per step and per fault: for logs, pipes and CI."""

    def __init__(self, console: Console, total: int) -> None:
        self.console = console
        self.total = total

    def __call__(self, event: dict) -> None:
        kind = event["type"]
        if kind == "step_started":
            self.console.print(f"[{event.get('step')}/{self.total}] {event['label']} "
                               f"({event['location']})", highlight=False)
        elif kind == "step_finished":
            extra = ""
            if "executed_duration_s" in event:
                extra = (f" in {event['executed_duration_s']:.2f} s (planned "
                         f"{event.get('planned_duration_s') or 0:.2f} s)")
            if "position_error_mm" in event:
                extra = (f": {event['position_error_mm']:.2f} mm, "
                         f"{event['angle_error_deg']:.3f}° from the expected pose")
            self.console.print(f"      passed{extra}", highlight=False)
        elif kind in ("fault", "operator_abort", "controlled_stop", "holding", "halt_requested",
                      "abort_requested", "latched_fault", "halt_unconfirmed", "halt_failed"):
            text = event.get("message") or event.get("reason") or kind.replace("_", " ")
            self.console.print(f"  !!  {kind.replace('_', ' ')}: {text}", highlight=False)


class LiveDisplay:
    """Step n/N, a progress bar per move, the joint table and the end-effector pose."""

    def __init__(self, console: Console, executor, title: str, bus: str, total: int) -> None:
        self.console = console
        self.ex = executor
        self.title = title
        self.bus = bus
        self.total = total
        self.step_text = "preflight: reading the arm"
        self.move_duration: float | None = None
        self.move_t = 0.0
        self.message = ""
        self.message_style = "yellow"
        self.target: np.ndarray | None = None
        self._prev: tuple[float, np.ndarray] | None = None
        self._velocity = np.zeros(executor.arm.dof)
        self._lock = threading.Lock()
        self.live = Live(self, console=console, refresh_per_second=10, transient=False)

    def __enter__(self) -> "LiveDisplay":
        self.live.__enter__()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.live.__exit__(*exc)

    def __call__(self, event: dict) -> None:
        kind = event["type"]
        with self._lock:
            if kind == "step_started":
                self.step_text = f"step {event.get('step')}/{self.total}: {event['label']}"
                self.move_duration = None
            elif kind == "move_planned":
                self.move_duration = event["duration_s"]
                self.move_t = 0.0
                self.target = np.array(event["target_deg"])
            elif kind == "setpoint":
                self.move_t = event["plan_t"]
            elif kind in ("fault", "operator_abort", "halt_unconfirmed", "halt_failed"):
                self.message, self.message_style = event["message"], "bold red"
            elif kind == "latched_fault":
                self.message, self.message_style = event["message"], "bold yellow"
            elif kind in ("controlled_stop", "abort_requested", "halt_requested", "paused"):
                self.message = kind.replace("_", " ")
                if kind == "controlled_stop":
                    self.move_duration = None   # the move's progress ends where it stopped
            elif kind == "run_finished":
                style = "bold green" if event["exit_code"] == 0 else "bold red"
                self.message, self.message_style = f"{event['status']}: {event['message']}", style

    def _update_velocity(self) -> None:
        m = self.ex.last
        if m is None:
            return
        if self._prev is not None and m.t > self._prev[0]:
            self._velocity = (m.user_deg - self._prev[1]) / (m.t - self._prev[0])
        self._prev = (m.t, m.user_deg.copy())

    def __rich__(self) -> Panel:
        with self._lock:
            self._update_velocity()
            m = self.ex.last
            table = Table(expand=False, box=None, padding=(0, 2))
            for col in ("joint", "position °", "velocity °/s", "target °", "state"):
                table.add_column(col, justify="right" if "°" in col else "left")
            for i, joint in enumerate(self.ex.arm.joints):
                pos = f"{m.user_deg[i]:8.2f}" if m is not None else "-"
                vel = f"{self._velocity[i]:7.2f}" if m is not None else "-"
                tgt = f"{self.target[i]:8.2f}" if self.target is not None else "-"
                state = "-"
                if m is not None and joint.module in m.short_state:
                    state = m.short_state[joint.module].describe()
                name = joint.name + (" (locked)" if joint.locked is not None else "")
                table.add_row(name, pos, vel, tgt, state)
            parts: list[Any] = [Text(self.step_text, style="bold")]
            if self.move_duration:
                done = min(self.move_t, self.move_duration)
                bar = Table.grid(padding=(0, 1))
                bar.add_row(ProgressBar(total=self.move_duration, completed=done, width=50),
                            Text(f"{done:.1f} / {self.move_duration:.1f} s"))
                parts.append(bar)
            parts.append(table)
            if m is not None:
                pose = kinematics.fk(self.ex.chain, np.radians(m.user_deg))
                rpy = np.degrees(kinematics.rpy_from_matrix(pose[:3, :3]))
                x, y, z = pose[:3, 3]
                parts.append(Text(f"end-effector  x {x:8.1f}  y {y:8.1f}  z {z:8.1f} mm   "
                                  f"roll {rpy[0]:7.2f}  pitch {rpy[1]:7.2f}  yaw {rpy[2]:7.2f} °"))
            if self.message:
                parts.append(Text(self.message, style=self.message_style))
            return Panel(Group(*parts), title=self.title, subtitle=self.bus)

