"""The live terminal view of a run with several arms: one status line per arm.

Each line says the arm, its step (n/N and label), the move's progress (a bar, done/planned
seconds), its end-effector position (mm, in the arm's base frame) and what happened last
(a fault, a stop, the verdict), cut to the terminal's width; an arm that was halted
gets a second line saying when, why and whether every module confirmed it:

    A  step 4/9: move j1 to 10°              ━━━━━━━━━━━━━━━━   0.7/  1.0 s  ee [  361.8,  -54.8,   47.9] mm
    B  step 4/9: wait for A_turned                                           ee [  365.9,   -0.1,   47.9] mm

Fed by every arm's events (its loop's listener: fields set, nothing drawn), drawn from
the arms' loops' idle time (:meth:`ArmsLiveView.on_idle`: as one arm's
:class:`~seqrun.cli.display.LiveDisplay`, at most 10 times a second, only when the slack
before the arm's next cycle is longer than a draw takes, and by one arm at a time), so
that it never delays a cycle of the arm it is drawn from. While the operator is asked
something it is off (:meth:`asking`). At the end the last state stays on the screen.
Labels and messages are printed literally (no rich markup).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, Iterator

from rich.console import Console, Group
from rich.live import Live
from rich.panel import Panel
from rich.text import Text

from seqrun.cli.display import halt_line
from seqrun.cli.output import fixed
from seqrun.service.kinematics import end_effector_pose

#: Width of a move's progress bar (characters).
BAR = 16
#: Width of the step's text (characters; longer is cut).
STEP = 36


@dataclass
class _ArmLine:
    """What one arm's line shows (set by its events)."""

    total: int
    step_text: str = "preflight: reading the arm"
    move_duration: float | None = None
    move_t: float = 0.0
    joints_deg: Any = None
    message: str = ""
    style: str = ""
    #: The arm's Halt (sent when, why, confirmed?): a line of its own under the arm's.
    halt: str = ""


class ArmsLiveView:
    """One status line per arm (see the module doc)."""

    #: Draws at most this often (seconds).
    INTERVAL = 0.1
    #: Margin kept free before the arm's next cycle, on top of the expected draw time.
    MARGIN = 0.001

    def __init__(self, console: Console, arms: Mapping[str, Any], totals: Mapping[str, int],
                 title: str) -> None:
        self.console = console
        self.arms = dict(arms)
        self.title = title
        self.lines = {a: _ArmLine(totals[a]) for a in arms}
        self.live: Live | None = None
        self._drawing = threading.Lock()
        self._last_draw = -1e9
        self._draw_cost = 0.002   # seconds; learnt from the draws
        self._width = max(len(a) for a in arms)

    # -------------------------------------------------------------- live on / off
    def _start(self) -> None:
        self.live = Live(self, console=self.console, auto_refresh=False, transient=True)
        self.live.start(refresh=True)
        self._last_draw = time.monotonic()

    def _stop(self) -> None:
        if self.live is not None:
            self.live.stop()
            self.live = None

    def __enter__(self) -> ArmsLiveView:
        self._start()
        return self

    def __exit__(self, *exc: Any) -> None:
        with self._drawing:
            self._stop()
        self.console.print(self)   # the final state stays on the screen

    @contextmanager
    def asking(self) -> Iterator[None]:
        """Off while the operator answers a question printed as a line."""
        with self._drawing:
            self._stop()
        try:
            yield
        finally:
            with self._drawing:
                self._start()

    # -------------------------------------------------------------- drawing
    def on_idle(self, arm_id: str, slack: float) -> None:
        """An arm's loop's idle hook: draw when due, when it fits into that arm's slack,
        and when no other arm is drawing (never waits for it)."""
        now = time.monotonic()
        if self.live is None or now - self._last_draw < self.INTERVAL:
            return
        if slack < self._draw_cost + self.MARGIN:
            return
        if not self._drawing.acquire(blocking=False):
            return
        try:
            if self.live is not None:
                self.live.refresh()
            self._last_draw = time.monotonic()
        finally:
            self._drawing.release()
        self._draw_cost = 0.7 * self._draw_cost + 0.3 * (time.monotonic() - now)

    # -------------------------------------------------------------- events
    def __call__(self, arm_id: str, event: Any) -> None:
        """One event of arm ``arm_id`` (on its loop's thread: only fields are set)."""
        line = self.lines.get(arm_id)
        if line is None:
            return
        kind = event["type"]
        if kind == "setpoint":
            line.move_t = event["plan_t"]
            line.joints_deg = event["measured_deg"]
        elif kind == "measurement":
            joints = event.get("joints_deg")
            if joints and all(v is not None for v in joints):
                line.joints_deg = joints
        elif kind == "step_started":
            line.step_text = f"step {event.get('step')}/{line.total}: {event['label']}"
            line.move_duration = None
        elif kind == "move_planned":
            line.move_duration, line.move_t = event["duration_s"], 0.0
        elif kind in ("fault", "operator_abort", "halt_unconfirmed", "halt_failed"):
            line.message, line.style, line.move_duration = event["message"], "bold red", None
            line.halt = halt_line(event) or line.halt
        elif kind == "latched_fault":
            line.message, line.style = event["message"], "bold yellow"
        elif kind in ("controlled_stop", "abort_requested", "halt_requested", "run_paused",
                      "resume_refused"):
            line.message, line.style = kind.replace("_", " "), "yellow"
            if kind == "controlled_stop":
                line.move_duration = None
        elif kind == "run_finished":
            line.message = f"{event['status']}: {event['message']}"
            line.style = "bold green" if event["exit_code"] == 0 else "bold red"
            line.move_duration = None

    def _line(self, arm_id: str) -> Text:
        line = self.lines[arm_id]
        text = Text(f"{arm_id:<{self._width}}  ", style="bold", no_wrap=True,
                    overflow="ellipsis")
        step = line.step_text if len(line.step_text) <= STEP else line.step_text[:STEP - 1] + "…"
        text.append(f"{step:<{STEP}}")
        if line.move_duration:
            done = min(line.move_t, line.move_duration)
            filled = int(round(BAR * done / line.move_duration))
            text.append("  ")
            text.append("━" * filled, style="green")
            text.append("━" * (BAR - filled), style="grey30")
            text.append(f" {done:5.1f}/{line.move_duration:5.1f} s")
        else:
            text.append(" " * (BAR + 16))
        if line.joints_deg is not None:
            (x, y, z), _ = end_effector_pose(self.arms[arm_id], line.joints_deg)
            text.append(f"  ee [{fixed(x, 1, 7)},{fixed(y, 1, 7)},{fixed(z, 1, 7)}] mm")
        if line.message:
            text.append(f"  {line.message}", style=line.style)
        return text

    def __rich__(self) -> Panel:
        parts: list[Text] = []
        for arm_id, line in self.lines.items():
            parts.append(self._line(arm_id))
            if line.halt:
                parts.append(Text(f"{' ' * self._width}  {line.halt}",
                                  style="bold white on red"))
        return Panel(Group(*parts), title=Text(self.title))
