"""What the operator's screen shows, rendered to a string (rich Console(record=True)).

Runs are at virtual time on the simulator; the live view is rendered after the run, as the
operator's screen is left when the run ends.
"""

from __future__ import annotations

import io
import re
from pathlib import Path

import pytest
from rich.console import Console

from projecttree import make_project
from runfolder import RunFolder
from seqrun.arm.description import load_arm
from seqrun.cli.display import LiveDisplay, PlainDisplay, fixed
from seqrun.clock import VirtualClock
from seqrun.service.connection import open_connection
from seqrun.results import EXIT_FAULT, EXIT_OK
from seqrun.service.runner import run_sequence
from seqrun.sequence.loader import load_sequence
from seqrun.sim.faults import parse_fault_spec
from seqrun.drivers.powercube.units import to_module_rad


def console() -> Console:
    return Console(record=True, file=io.StringIO(), width=160, color_system=None)


def project(tmp_path: Path, name: str, steps: str) -> Path:
    root = tmp_path / "project"
    if not root.exists():
        make_project(root)
    path = root / "sequences" / f"{name}.yaml"
    path.write_text(f"name: {name}\ndescription: a test\nsteps:\n{steps}", encoding="utf-8")
    return path


def run_with_displays(path: Path, tmp_path: Path, faults=()):
    """Run ``path`` with a live view (never started: rendered afterwards) and the plain
    display; returns (outcome, live view, live console, plain console)."""
    loaded = load_sequence(path)
    arm = load_arm(loaded.arm_path)
    connection = open_connection(force_sim=True, clock=VirtualClock(),
                                 faults=[parse_fault_spec(f) for f in faults])
    live_console, plain_console = console(), console()
    views = {}

    def attach(executor):
        views["live"] = LiveDisplay(live_console, executor.arm, executor.events.subscribe(
            maxsize=2000, name="live view"), f"seqrun: {loaded.name}", "sim", len(loaded.steps))
        executor.listeners += [views["live"], PlainDisplay(plain_console, len(loaded.steps))]

    try:
        outcome = run_sequence(loaded, arm, connection, log_dir=tmp_path / "run",
                               confirm=lambda prompt: True, on_executor=attach,
                               html_report=False)
    finally:
        connection.close()
    return outcome, views["live"], live_console, plain_console


def rows(text: str) -> dict[str, str]:
    """The joint table's rows by joint name."""
    out = {}
    for line in text.splitlines():
        m = re.match(r"\W*(j\d)\b(.*)$", line.strip("│ "))
        if m:
            out[m.group(1)] = m.group(2)
    return out


def test_after_home_every_joint_shows_the_modules_state_not_the_last_cycle(tmp_path):
    path = project(tmp_path, "home", "  - reset: {}\n  - home: {}\n")
    outcome, view, live_console, _ = run_with_displays(path, tmp_path)
    assert outcome.result.exit_code == EXIT_OK
    live_console.print(view)
    table = rows(live_console.export_text())
    assert len(table) == 7
    for joint, row in table.items():
        assert "HOME_OK" in row and "NOT_OK" not in row, (joint, row)


def test_after_a_fault_the_screen_says_halt_sent_and_nothing_moves(tmp_path):
    path = project(tmp_path, "fault", "  - include: startup.yaml\n"
                                      "  - move: {joints: {j1: 40, j2: -60}, velocity_deg_s: {j1: 10, j2: 10},"
                                      " label: Long move}\n")
    outcome, view, live_console, plain_console = run_with_displays(
        path, tmp_path, faults=["2:tow_error@2"])
    result = outcome.result
    assert result.exit_code == EXIT_FAULT and result.fault["halt_sent"]
    live_console.print(view)
    screen = live_console.export_text()
    table = rows(screen)
    for joint, row in table.items():
        assert "MOTION" not in row, (joint, row)
        assert "HALTED" in row, (joint, row)
        velocity = row.replace("(locked)", "").split()[1]
        assert velocity == "0.00", (joint, row)
    halt = [line for line in screen.splitlines() if "HALT sent at" in line]
    assert len(halt) == 1
    assert re.search(r"HALT sent at \d\d:\d\d:\d\d, t = \d+\.\d\d s \(confirmed by every "
                     r"module\): tow_error: module 2 \(j2\)", halt[0]), halt[0]
    # The plain display says it too, and keeps the message's [state ...] part.
    plain = plain_console.export_text()
    assert "HALT sent at" in plain and "tow_error" in plain
    assert "[state " in plain


def test_labels_and_messages_are_printed_literally(tmp_path):
    """Rich markup in a label or message is text: '[/bold] up' used to raise MarkupError,
    drop the display and silence every later fault line; '[state …]' was swallowed."""
    path = project(tmp_path, "markup",
                   "  - include: startup.yaml\n"
                   "  - move: {joints: {j1: 40}, velocity_deg_s: {j1: 10}, label: '[/bold] up'}\n"
                   "  - move: {joints: {j1: 0}, label: '[red]down[/red] [ruckig]'}\n")
    outcome, view, live_console, plain_console = run_with_displays(
        path, tmp_path, faults=["1:tow_error@2"])
    assert outcome.result.exit_code == EXIT_FAULT
    plain = plain_console.export_text()
    assert "[4/5] [/bold] up (" in plain
    fault_lines = [line for line in plain.splitlines() if "!!  fault:" in line]
    assert len(fault_lines) == 1 and "[state " in fault_lines[0]
    assert not RunFolder(tmp_path / "run").events("listener_failed")
    live_console.print(view)
    screen = live_console.export_text()
    assert "[state " in screen


def test_a_fault_message_is_printed_literally():
    c = console()
    PlainDisplay(c, 3)({"type": "fault", "message": "[ruckig] cannot plan [bold]x",
                        "cause": "planning", "halt_sent": True, "t": 1.0})
    text = c.export_text()
    assert "fault: [ruckig] cannot plan [bold]x" in text
    assert "HALT sent at" in text and "planning: [ruckig] cannot plan [bold]x" in text


@pytest.mark.parametrize("value, text", [(-0.0001, "0.00"), (-0.004, "0.00"), (0.0, "0.00"),
                                         (-0.006, "-0.01"), (1.005, "1.00"), (-2.5, "-2.50")])
def test_fixed_never_prints_minus_zero(value, text):
    assert fixed(value).strip() == text


def test_a_fault_message_names_limits_in_user_degrees_not_module_radians(tmp_path):
    """A module that stops answering while set_limits writes: the message used to read
    'no acknowledge to SetExtended MIN_POS = -3.141592653589793'."""
    path = project(tmp_path, "limits", "  - reset: {}\n  - home: {}\n"
                                       "  - set_limits: {limits_deg: {j4: [-100, 100]}}\n")
    first, *_ = run_with_displays(path, tmp_path / "a")
    assert first.result.exit_code == EXIT_OK
    started = next(e["t"] for e in RunFolder(tmp_path / "a" / "run").events("step_started")
                   if e["step"] == 3)
    outcome, *_ = run_with_displays(path, tmp_path / "b",
                                    faults=[f"4:missing@{started + 1e-6:.6f}"])
    message = outcome.result.fault["message"]
    assert outcome.result.exit_code == EXIT_FAULT
    assert "SetExtended MIN_POS (j4) = -100.00°" in message, message
    assert "3.14" not in message and "rad" not in message


def test_request_descriptions_in_user_coordinates(arm):
    from seqrun.errors import ModuleTimeoutError
    from seqrun.powercube.codec import SetMotion, SetParam
    from seqrun.powercube.protocol import MotionMode, ParamId
    from seqrun.drivers.powercube.messages import user_message

    j2 = arm.joint("j2")
    exc = ModuleTimeoutError(j2.module, "whatever", 0.05,
                             request=SetParam(j2.module, ParamId.MAX_POS, to_module_rad(j2, -1e-9)))
    assert user_message(exc, arm) == (f"module {j2.module}: no acknowledge to SetExtended "
                                      "MAX_POS (j2) = 0.00° within 50 ms")
    exc = ModuleTimeoutError(j2.module, "x", 0.05, request=SetMotion(
        j2.module, MotionMode.FRAMP_ACK, to_module_rad(j2, 45.0)))
    assert "SetMotion FRAMP_ACK (j2) 45.00°" in user_message(exc, arm)


def test_junit_names_each_step_once(tmp_path):
    import xml.etree.ElementTree as ET

    path = project(tmp_path, "junit", "  - reset: {}\n  - confirm: Ready?\n"
                                      "  - home: {label: Motors on}\n")
    outcome, *_ = run_with_displays(path, tmp_path)
    assert outcome.result.exit_code == EXIT_OK
    suite = ET.parse(tmp_path / "run" / "junit.xml").getroot().find("testsuite")
    names = [case.get("name") for case in suite.findall("testcase")]
    assert names == ["01 reset all modules", "02 confirm: Ready?", "03 home: Motors on"]


def test_no_minus_zero_in_pose_numbers_or_the_status_table():
    from seqrun.cli.arm_commands import status_table
    from seqrun.cli.pose import format_numbers

    assert format_numbers([-0.0001, -0.0004, 1.5]) == "[0.000, 0.000, 1.500]"
    status = {"joints": [{"joint": "j1", "module": 1, "position_deg": -0.0002,
                          "velocity_deg_s": -0.0001, "state": "HOME_OK", "fault": False}],
              "end_effector": {"position_mm": [0.0, 0.0, 1000.0], "rpy_deg": [0.0, 0.0, 0.0]}}
    c = console()
    c.print(status_table(status, "arm"))
    text = c.export_text()
    assert "-0.000" not in text and "0.000" in text


def test_the_live_view_renders_on_the_control_loop_thread_only(tmp_path):
    """No display thread competes with the 100 Hz loop: every render of the live view runs
    on the loop's thread, from the executor's idle time (issue: rich's 10 Hz refresh thread
    took the interpreter lock from the loop)."""
    import threading

    path = project(tmp_path, "live", "  - include: startup.yaml\n"
                                     "  - move: {joints: {j1: 20}, label: Up}\n")
    loaded = load_sequence(path)
    arm = load_arm(loaded.arm_path)
    connection = open_connection(force_sim=True, clock=VirtualClock())
    screen = Console(file=io.StringIO(), force_terminal=True, width=120)
    renders: list[str] = []
    threads_before = set(threading.enumerate())
    threads_during: set = set()

    class Recording(LiveDisplay):
        # Render in every idle slot (no rate limit, no fit check): on a loaded test host a
        # render may not fit the loop's 10 ms slack, and then the view rightly skips it.
        INTERVAL = 0.0
        MARGIN = -1.0

        def __rich__(self):
            renders.append(threading.current_thread().name)
            threads_during.update(threading.enumerate())
            return super().__rich__()

    def attach(executor):
        view = Recording(screen, executor.arm, executor.events.subscribe(maxsize=2000),
                         "live", "sim", len(loaded.steps))
        executor.listeners.append(view)
        executor.idle_hooks.append(view.on_idle)  # as ArmSession.add_idle_hook does
        view.__enter__()
        views.append(view)

    views: list = []
    try:
        outcome = run_sequence(loaded, arm, connection, log_dir=None,
                               confirm=lambda prompt: True, on_executor=attach)
    finally:
        views[0].__exit__(None, None, None)
        connection.close()
    assert outcome.result.exit_code == EXIT_OK
    assert len(renders) >= 5  # start, idle-time renders during the run, final
    assert set(renders) == {threading.main_thread().name}
    new_threads = {t for t in threads_during - threads_before
                   if not t.name.startswith("seqrun")}  # the simulator's and watchdog's own
    assert not new_threads, new_threads


def test_a_run_refused_in_preflight_still_shows_where_the_arm_stands(tmp_path):
    """The live view reads only events: the preflight's reading gives the joint table
    (a run that ends there has no other measurement)."""
    path = project(tmp_path, "early", "  - move: {joints: {j1: 10}}\n")  # no start-up
    outcome, view, live_console, _ = run_with_displays(path, tmp_path)
    assert outcome.result.status == "invalid"
    live_console.print(view)
    table = rows(live_console.export_text())
    assert table["j2"].split()[0] == "-90.00", table["j2"]


def test_request_descriptions_give_rates_without_the_offset(arm):
    """Positions get the joint's offset, rates only the unit (one conversion for both
    SetExtended and SetMotion); values that are not angles are not described."""
    import math

    from seqrun.powercube.codec import SetMotion, SetParam
    from seqrun.powercube.protocol import MotionMode, ParamId
    from seqrun.drivers.powercube.messages import describe_request

    j2 = arm.joint("j2")
    rate = math.radians(12.5)
    assert describe_request(SetParam(j2.module, ParamId.MAX_VEL, rate), arm) == (
        "SetExtended MAX_VEL (j2) = 12.50 °/s")
    assert describe_request(SetParam(j2.module, ParamId.MAX_ACC, rate), arm) == (
        "SetExtended MAX_ACC (j2) = 12.50 °/s²")
    assert describe_request(SetMotion(j2.module, MotionMode.FVEL_ACK, -rate), arm) == (
        "SetMotion FVEL_ACK (j2) -12.50 °/s")
    step = SetMotion(j2.module, MotionMode.FSTEP_ACK, to_module_rad(j2, -30.0), time_ms=40)
    assert describe_request(step, arm) == "SetMotion FSTEP_ACK (j2) -30.00° in 40 ms"
    assert describe_request(SetParam(j2.module, ParamId.CUBE_STATE, 0), arm) is None
