"""What the operator sees during a run: a rich live view on a terminal, plain lines otherwise.

Both consume the arm session's typed events (:mod:`seqrun.events`) and nothing else: the
live view has a subscription of its own (a bounded queue: publishing never waits for it),
which it drains and renders from the control loop's own idle time (:meth:`LiveDisplay.on_idle`,
given to :meth:`ArmSession.add_idle_hook`: called with the slack before the loop sleeps until
its next cycle), at most 10 times a second and only when the slack is longer than a render
takes, so the display can neither delay a cycle nor compete with the loop from a thread of
its own. Joints, velocities and
state flags come from ``measurement`` events. While the operator is asked something the
live view is off and the question is an ordinary line where the cursor is
(:meth:`LiveDisplay.asking`). The plain display is called with each event (by a listener
thread of the session, or as a recorder).

Everything the user wrote (labels, prompts) and every message is printed literally: rich
markup is never interpreted in it.
"""

from __future__ import annotations

import time
from contextlib import contextmanager
from datetime import datetime
from typing import TYPE_CHECKING, Any, Iterator

import numpy as np
from rich.console import Console, Group
from rich.live import Live
from rich.panel import Panel
from rich.text import Text

from seqrun.service.kinematics import end_effector_pose
from seqrun.cli.output import fixed

if TYPE_CHECKING:
    from seqrun.events import Subscription


def halt_line(event: dict) -> str | None:
    """The line a fault event earns on the screen: Halt sent (when, why, confirmed?)."""
    if event.get("type") != "fault" or "halt_sent" not in event:
        return None
    cause = event.get("cause") or "fault"
    when = f"{datetime.now().strftime('%H:%M:%S')}, t = {fixed(event.get('t', 0.0))} s"
    if not event["halt_sent"]:
        return f"HALT could NOT be sent ({when}): {cause}: {event.get('message', '')}"
    confirmed = event.get("halt_confirmed")
    check = ("" if confirmed is None else " (confirmed by every module)" if confirmed
             else f" (NOT confirmed by module(s) "
                  f"{', '.join(map(str, event.get('modules_not_halted') or [])) or '?'})")
    return f"HALT sent at {when}{check}: {cause}: {event.get('message', '')}"


def iteration_text(event: dict) -> str:
    """' (2/3)' for an iteration of a step repeated 3 times, ' (2, at most 10)' of one
    repeated while a condition holds; '' for any other step."""
    if event.get("iteration") is None:
        return ""
    if event.get("iterations") is not None:
        return f" ({event['iteration']}/{event['iterations']})"
    return f" ({event['iteration']}, at most {event.get('max_iterations')})"


def skipped_text(event: dict) -> str:
    """Why a step did not run: its condition and the value it had."""
    value = "true" if event["value"] else "false"
    return f"skipped: {event['key']} '{event['condition']}' was {value}"


def block_text(event: dict) -> str:
    """A block's step that failed (and what follows), or how a block ended."""
    if event["type"] == "block_step_failed":
        then = "the block's rescue runs" if event["rescue"] else "the block fails"
        return f"failed: {event['message']} ({then})"
    shown = f" ({event['label']})" if event["label"] != "block" else ""
    return f"block {event['block']}{shown} at {event['location']}: {event['status']}"


class PlainDisplay:
    """One line per step and per fault: for logs, pipes and CI."""

    def __init__(self, console: Console, total: int) -> None:
        self.console = console
        self.total = total
        self._label = ""   # the running step's, for the lines of its iterations

    def _print(self, text: str, **style: Any) -> None:
        self.console.print(text, highlight=False, markup=False, **style)

    def __call__(self, event: dict) -> None:
        kind = event["type"]
        if kind == "step_started":
            self._label = event["label"]
            self._print(f"[{event.get('step')}/{self.total}] {event['label']} "
                        f"({event['location']}){iteration_text(event)}")
        elif kind == "step_iteration":
            self._print(f"[{event.get('step')}/{self.total}] {self._label}"
                        f"{iteration_text(event)}")
        elif kind == "step_skipped":
            self._print(f"[{event.get('step')}/{self.total}] {event['label']} "
                        f"({event['location']})")
            self._print(f"      {skipped_text(event)}")
        elif kind == "step_retry":
            self._print(f"      retry {event['attempt']}/{event['times']} after: "
                        f"{event['message']}")
        elif kind == "operator_choice":  # on_fail: pause
            self._print(f"      the operator chose {event['choice']} ({event['by']}) after: "
                        f"{event['message']}")
        elif kind in ("block_step_failed", "block_finished"):
            self._print(f"      {block_text(event)}")
        elif kind == "step_finished":
            extra = ""
            if "executed_duration_s" in event:
                extra = (f" in {fixed(event['executed_duration_s'])} s (planned "
                         f"{fixed(event.get('planned_duration_s') or 0)} s)")
            if "position_error_mm" in event:
                extra = (f": {fixed(event['position_error_mm'])} mm, "
                         f"{fixed(event['angle_error_deg'], 3)}° from the expected pose")
            self._print(f"      passed{extra}")
        elif kind in ("fault", "operator_abort", "controlled_stop", "holding", "halt_requested",
                      "abort_requested", "latched_fault", "halt_unconfirmed", "halt_failed"):
            text = event.get("message") or event.get("reason") or kind.replace("_", " ")
            self._print(f"  !!  {kind.replace('_', ' ')}: {text}")
            line = halt_line(event)
            if line is not None:
                self._print(f"  !!  {line}")


class LiveDisplay:
    """Step n/N, a progress bar per move, the joint table and the end-effector pose."""

    #: Renders at most this often (seconds).
    INTERVAL = 0.1
    #: Margin kept free before the next cycle, on top of the expected render time.
    MARGIN = 0.001

    def __init__(self, console: Console, arm, subscription: Subscription, title: str,
                 bus: str, total: int) -> None:
        """``subscription``: the view's own queue of the session's events (it closes it on
        exit); :meth:`on_idle` is what the owner hands the loop to render in its slack."""
        self.console = console
        self.arm = arm
        self.subscription = subscription
        #: The latest measurement event (joints, velocities, flags).
        self.measured = None
        self.title = title
        self.bus = bus
        self.total = total
        self.step_text = "preflight: reading the arm"
        self._step_head = ""   # the running step's line without its iteration
        self.move_duration: float | None = None
        self.move_t = 0.0
        self.message = ""
        self.message_style = "yellow"
        self.halt_text = ""
        self.target: np.ndarray | None = None
        self._last_render = -1e9
        self._render_cost = 0.002  # seconds; learnt from the renders
        self.live: Live | None = None

    # -------------------------------------------------------------- live on / off
    def _start(self) -> None:
        # A fresh Live each time: its cursor bookkeeping must not reach above the lines
        # printed while it was off (the operator's question and answer).
        self.live = Live(self, console=self.console, auto_refresh=False, transient=True)
        self.live.start(refresh=True)
        self._last_render = time.monotonic()

    def _stop(self) -> None:
        if self.live is not None:
            self.live.stop()  # transient: the panel goes, the lines above it stay
            self.live = None

    def __enter__(self) -> "LiveDisplay":
        self._start()
        return self

    def __exit__(self, *exc: Any) -> None:
        self._stop()
        self.console.print(self)  # the final state stays on the screen
        self.subscription.close()

    @contextmanager
    def asking(self, context: str | None = None) -> Iterator[None]:
        """The live view is off while the operator answers a question printed as a line."""
        if context is not None:
            self.step_text = context
        self._stop()
        try:
            yield
        finally:
            self._start()

    # -------------------------------------------------------------- rendering
    def on_idle(self, slack: float) -> None:
        """The loop's idle hook: render when due and when it fits into the slack."""
        now = time.monotonic()
        if self.live is None or now - self._last_render < self.INTERVAL:
            return
        if slack < self._render_cost + self.MARGIN:
            return
        self.refresh()
        cost = time.monotonic() - now
        self._render_cost = 0.7 * self._render_cost + 0.3 * cost

    def refresh(self) -> None:
        if self.live is not None:
            self.live.refresh()
        self._last_render = time.monotonic()

    # -------------------------------------------------------------- events
    def _drain(self) -> None:
        for event in self.subscription.drain():
            self(event)

    def __call__(self, event) -> None:
        # No lock: draining, idle hooks and renders all run on the control loop's thread
        # (a signal handler that emits only sets fields).
        kind = event["type"]
        if kind == "measurement":
            self.measured = event
            return
        if kind == "step_started":
            self._step_head = f"step {event.get('step')}/{self.total}: {event['label']}"
            self.step_text = self._step_head + iteration_text(event)
            self.move_duration = None
        elif kind == "step_iteration":
            self.step_text = self._step_head + iteration_text(event)
        elif kind == "step_skipped":
            self.message, self.message_style = (f"step {event.get('step')}: "
                                                f"{skipped_text(event)}", "yellow")
        elif kind in ("block_step_failed", "block_finished"):
            self.message, self.message_style = block_text(event), "yellow"
        elif kind == "move_planned":
            self.move_duration = event["duration_s"]
            self.move_t = 0.0
            self.target = np.array(event["target_deg"])
        elif kind == "setpoint":
            self.move_t = event["plan_t"]
        elif kind in ("fault", "operator_abort", "halt_unconfirmed", "halt_failed"):
            self.message, self.message_style = event["message"], "bold red"
            self.halt_text = halt_line(event) or self.halt_text
            self.move_duration = None
        elif kind == "latched_fault":
            self.message, self.message_style = event["message"], "bold yellow"
        elif kind in ("controlled_stop", "abort_requested", "halt_requested", "run_paused",
                      "resume_refused"):
            self.message = kind.replace("_", " ")
            if kind == "controlled_stop":
                self.move_duration = None   # the move's progress ends where it stopped
        elif kind == "run_finished":
            style = "bold green" if event["exit_code"] == 0 else "bold red"
            self.message, self.message_style = f"{event['status']}: {event['message']}", style

    @staticmethod
    def _state(m, joint: str) -> tuple[str, bool]:
        """The module's state text and whether it is moving, from the freshest reading
        (its state word where one was read, else the short state)."""
        flags = (m.flags or {}).get(joint)
        if flags is None:
            return "-", False
        return "|".join(flags) or "OK", "MOTION" in flags

    def __rich__(self) -> Panel:
        # Fixed-width text lines, not a rich Table: a Table's layout costs many times more,
        # and the render has to fit into the loop's slack.
        self._drain()
        m = self.measured
        width = max(len(self._joint_label(j)) for j in self.arm.joints) + 2
        lines = [Text(f"  {'joint':<{width}}{'position °':>12}{'velocity °/s':>15}"
                      f"{'target °':>11}    state", style="bold")]
        for i, joint in enumerate(self.arm.joints):
            pos = vel = state = "-"
            if m is not None:
                state, moving = self._state(m, joint.name)
                pos = fixed(m.joints_deg[i], 2)
                # A module that does not report motion stands still (Halt, end of ramp);
                # an estimate over the last samples would say otherwise.
                velocity = m.velocities_deg_s[i] if m.velocities_deg_s else 0.0
                vel = fixed(velocity if moving else 0.0, 2)
            tgt = fixed(self.target[i], 2) if self.target is not None else "-"
            lines.append(Text(f"  {self._joint_label(joint):<{width}}{pos:>12}{vel:>15}"
                              f"{tgt:>11}    {state}"))
        parts: list[Any] = [Text(self.step_text, style="bold")]
        if self.move_duration:
            done = min(self.move_t, self.move_duration)
            filled = int(round(50 * done / self.move_duration))
            parts.append(Text.assemble(("━" * filled, "green"), ("━" * (50 - filled), "grey30"),
                                       f" {done:.1f} / {self.move_duration:.1f} s"))
        parts.extend(lines)
        if m is not None:
            (x, y, z), rpy = end_effector_pose(self.arm, m.joints_deg)
            parts.append(Text(f"end-effector  x {fixed(x, 1, 8)}  y {fixed(y, 1, 8)}  "
                              f"z {fixed(z, 1, 8)} mm   roll {fixed(rpy[0], 2, 7)}  "
                              f"pitch {fixed(rpy[1], 2, 7)}  yaw {fixed(rpy[2], 2, 7)} °"))
        if self.halt_text:
            parts.append(Text(self.halt_text, style="bold white on red"))
        if self.message:
            parts.append(Text(self.message, style=self.message_style))
        return Panel(Group(*parts), title=Text(self.title), subtitle=Text(self.bus))

    @staticmethod
    def _joint_label(joint) -> str:
        return joint.name + (" (locked)" if joint.locked is not None else "")
