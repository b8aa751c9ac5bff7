"""Signals at the worst moments, in process at virtual time.

A Python signal handler runs in the main thread between two bytecodes of whatever that
thread does. The run's handler (:class:`seqrun.cli.interrupts.RunSignals`) is called here
directly from *inside* every lock the control loop takes (the live view's, the client's,
the clock's, the simulated bus's) and from inside a run-folder write, as a
signal arriving there would run it. Before the handlers only posted requests, such a call
deadlocked the run (the handler took the executor's lock and called the live view, which
takes its own non-reentrant lock). Each run must end, within a bound, the way the signal
asks: SIGINT -> controlled stop (130), SIGTERM -> Halt (130), SIGHUP / SIGQUIT -> Halt
(exit 3), a second SIGINT during the controlled stop -> Halt; and leave a finished run
folder. (The runs draw no report.html: nothing here reads it, and it is drawn after the
run has ended.)
"""

from __future__ import annotations

import io
import signal
import threading
from pathlib import Path

import pytest
from rich.console import Console

from projecttree import ROOT
from runfolder import RunFolder
from seqrun.runfolder import logfile
from seqrun.arm.description import load_arm
from seqrun.cli.display import LiveDisplay, PlainDisplay
from seqrun.cli.interrupts import RunSignals
from seqrun.clock import VirtualClock
from seqrun.service.connection import open_connection
from seqrun.results import EXIT_FAULT, EXIT_OK, EXIT_OPERATOR_ABORT
from seqrun.service.runlog import read_trace
from seqrun.service.runner import run_sequence
from seqrun.sequence.loader import load_sequence
from seqrun.stop_requests import StopRequests

SIGNALS = {"SIGINT": signal.SIGINT, "SIGTERM": signal.SIGTERM, "SIGHUP": signal.SIGHUP,
           "SIGQUIT": signal.SIGQUIT}
#: A run that does not end within this many real seconds is taken for a deadlock.
DEADLOCK_AFTER_S = 60


class HookLock:
    """A lock that calls ``hook`` each time it has been acquired (while holding it)."""

    def __init__(self, lock, hook) -> None:
        self._lock = lock
        self._hook = hook

    def acquire(self, *args, **kwargs):
        got = self._lock.acquire(*args, **kwargs)
        if got:
            self._hook()
        return got

    def release(self):
        self._lock.release()

    def __enter__(self):
        self.acquire()
        return self

    def __exit__(self, *exc):
        self.release()


class Injector:
    """Fires the signals of ``plan`` through the run's handler, each at the ``nth``
    occasion (a lock acquisition, a write) once its condition holds."""

    def __init__(self, signals: RunSignals, plan: list[tuple[int, str]], nth: int) -> None:
        self.signals = signals
        self.plan = list(plan)       # (signal number, "moving" | "stopping")
        self.nth = nth
        self.count = 0
        self.fired: list[int] = []
        self.executor = None
        self.events: list[dict] = []

    def phase_ok(self, phase: str) -> bool:
        kinds = [e["type"] for e in self.events]
        if phase == "moving":   # inside the move, at speed
            begun = len(kinds) - kinds[::-1].index("move_planned") if "move_planned" in kinds else None
            return (begun is not None and "step_finished" not in kinds[begun:]
                    and kinds[begun:].count("setpoint") >= 3)
        return "controlled_stop" in kinds and "holding" not in kinds

    def __call__(self) -> None:
        if not self.plan or not self.phase_ok(self.plan[0][1]):
            return
        self.count += 1
        if self.count >= self.nth:
            signum, _ = self.plan.pop(0)
            self.count = 0
            self.fired.append(signum)
            self.signals.handle(signum, None)   # as the signal would, here and now


def run_injected(tmp_path: Path, where: str, plan: list[tuple[int, str]], nth: int):
    loaded = load_sequence(ROOT / "sequences" / "totem.yaml")
    arm = load_arm(loaded.arm_path)
    clock = VirtualClock()
    connection = open_connection(force_sim=True, clock=clock)
    requests = StopRequests()
    signals = RunSignals(requests)
    injector = Injector(signals, plan, nth)
    console = Console(file=io.StringIO(), width=100)

    def attach(executor) -> None:
        injector.executor = executor
        executor.listeners.insert(0, injector.events.append)
        live = LiveDisplay(console, executor.arm, executor.events.subscribe(maxsize=2000),
                           "test", "sim", len(loaded.steps))
        executor.idle_hooks.append(live.on_idle)

        def live_view(event: dict) -> None:
            # The live view holds no lock (it draws on the loop's thread): a signal that
            # arrives while it handles an event stands for "inside the live view".
            if where == "live_view":
                injector()
            live(event)

        executor.listeners += [live_view, PlainDisplay(console, len(loaded.steps))]
        targets = {"client": (executor.client, "_lock"),
                   "clock": (clock, "_lock"), "sim_bus": (connection.bus.arm, "_lock")}
        if where in targets:
            owner, attr = targets[where]
            setattr(owner, attr, HookLock(getattr(owner, attr), injector))

    real_write = logfile._write

    def write(fd, data):
        n = real_write(fd, data)
        if where == "log_write":
            injector()
        return n

    outcome: dict = {}

    def target() -> None:
        try:
            logfile._write = write
            outcome["run"] = run_sequence(loaded, arm, connection, log_dir=tmp_path / "run",
                                          confirm=lambda prompt: True, on_executor=attach,
                                          requests=requests, html_report=False)
        except BaseException as exc:  # noqa: BLE001 - reported by the test
            outcome["error"] = exc
        finally:
            logfile._write = real_write

    thread = threading.Thread(target=target, daemon=True)
    thread.start()
    thread.join(DEADLOCK_AFTER_S)
    assert not thread.is_alive(), f"deadlock: signal {injector.fired} inside {where}"
    connection.close()
    assert "error" not in outcome, repr(outcome.get("error"))
    return outcome["run"], injector


WHERE = ("live_view", "client", "clock", "sim_bus", "log_write")


def _is_halt(msg) -> bool:
    return msg.arbitration_id == 0x100 and bytes(msg.data[:1]) == b"\x02" and not msg.is_rx


def assert_finished_folder(folder: Path, code: int) -> dict:
    report = RunFolder(folder).report()
    assert report["exit_code"] == code and report["status"] != "running"
    junit = (folder / "junit.xml").read_text()
    assert junit.rstrip().endswith("</testsuites>")
    last = RunFolder(folder).events()[-1]
    assert last["type"] == "run_finished" and last["exit_code"] == code
    assert not list(folder.glob("*.tmp"))
    return report


@pytest.mark.parametrize("nth", [1, 7])
@pytest.mark.parametrize("where", WHERE)
@pytest.mark.parametrize("name", ["SIGINT", "SIGTERM", "SIGHUP", "SIGQUIT"])
def test_a_signal_inside_any_lock_stops_the_run_as_asked(tmp_path, name, where, nth):
    run, injector = run_injected(tmp_path, where, [(SIGNALS[name], "moving")], nth)
    assert injector.fired == [SIGNALS[name]], "the injection point was never reached"
    result = run.result
    halts = [m for m in read_trace(tmp_path / "run") if _is_halt(m)]
    if name == "SIGINT":
        assert result.exit_code == EXIT_OPERATOR_ABORT and result.fault is None, result
        assert halts == []
        kinds = [e["type"] for e in injector.events]
        assert "controlled_stop" in kinds and "holding" in kinds
    elif name == "SIGTERM":
        assert result.exit_code == EXIT_OPERATOR_ABORT, result
        assert result.fault["cause"] == "operator_halt" and result.fault["halt_sent"]
        assert halts
    else:
        assert result.exit_code == EXIT_FAULT, result
        assert result.fault["cause"] == "signal" and result.fault["halt_sent"]
        assert name in result.fault["message"]
        assert halts
    assert_finished_folder(tmp_path / "run", result.exit_code)


@pytest.mark.parametrize("where", WHERE)
def test_a_second_sigint_inside_any_lock_during_the_controlled_stop_halts(tmp_path, where):
    run, injector = run_injected(
        tmp_path, where, [(signal.SIGINT, "moving"), (signal.SIGINT, "stopping")], 3)
    assert injector.fired == [signal.SIGINT, signal.SIGINT]
    result = run.result
    assert result.exit_code == EXIT_OPERATOR_ABORT
    assert result.fault["cause"] == "operator_halt" and result.fault["halt_sent"]
    kinds = [e["type"] for e in injector.events]
    assert "controlled_stop" in kinds and "holding" not in kinds
    assert any(_is_halt(m) for m in read_trace(tmp_path / "run"))
    assert_finished_folder(tmp_path / "run", EXIT_OPERATOR_ABORT)


def test_without_a_signal_the_injected_run_passes(tmp_path):
    """The control case: the hooks alone change nothing."""
    run, injector = run_injected(tmp_path, "live_view", [], 1)
    assert run.result.exit_code == EXIT_OK and injector.fired == []
    assert_finished_folder(tmp_path / "run", EXIT_OK)


# ----------------------------------------------------------------------------- questions
def question_run(tmp_path: Path, answer):
    """totem.yaml with a real question at its confirm step; ``answer(signals)`` plays the
    operator (returns the line read, or calls the handler as a signal would)."""
    loaded = load_sequence(ROOT / "sequences" / "totem.yaml")
    arm = load_arm(loaded.arm_path)
    connection = open_connection(force_sim=True, clock=VirtualClock())
    requests = StopRequests()
    signals = RunSignals(requests)

    def confirm(prompt: str) -> bool:
        line = signals.read_answer(readline=lambda: answer(signals))
        return line is not None and line.strip() == "y"

    try:
        return run_sequence(loaded, arm, connection, log_dir=tmp_path / "run",
                            confirm=confirm, requests=requests, html_report=False)
    finally:
        connection.close()


def test_ctrl_c_at_a_question_is_a_no_and_nothing_moves(tmp_path):
    def operator(signals):
        signals.handle(signal.SIGINT)       # raises KeyboardInterrupt out of the read
        raise AssertionError("the read was not interrupted")

    run = question_run(tmp_path, operator)
    assert run.result.exit_code == EXIT_OPERATOR_ABORT and run.result.fault is None
    report = assert_finished_folder(tmp_path / "run", EXIT_OPERATOR_ABORT)
    assert report["status"] == "aborted"
    assert not [m for m in read_trace(tmp_path / "run") if _is_halt(m)]


@pytest.mark.parametrize("name, code, cause", [("SIGTERM", EXIT_OPERATOR_ABORT, "operator_halt"),
                                                ("SIGHUP", EXIT_FAULT, "signal")])
def test_a_halt_signal_at_a_question_then_end_of_input_reports_the_halt(tmp_path, name, code,
                                                                          cause):
    """Issue: SIGTERM during a question, then EOF, ended with fault: null though the Halt
    was sent."""
    def operator(signals):
        try:
            signals.handle(SIGNALS[name])
        except KeyboardInterrupt:
            pass                              # as if the read had gone on: end of input
        return ""

    run = question_run(tmp_path, operator)
    assert run.result.exit_code == code
    assert run.result.fault["cause"] == cause and run.result.fault["halt_sent"]
    report = assert_finished_folder(tmp_path / "run", code)
    assert report["fault"]["cause"] == cause and name in report["fault"]["message"]
    assert [m for m in read_trace(tmp_path / "run") if _is_halt(m)]


def test_a_signal_before_the_question_answers_it_without_waiting(tmp_path):
    loaded = load_sequence(ROOT / "sequences" / "totem.yaml")
    signals = RunSignals(StopRequests())
    signals.handle(signal.SIGINT)
    assert signals.read_answer(readline=lambda: pytest.fail("blocked on the read")) is None
    assert loaded.steps   # (the sequence used by the other tests has a question)


def test_end_of_input_at_a_question_is_an_operator_abort(tmp_path):
    run = question_run(tmp_path, lambda signals: "")
    assert run.result.exit_code == EXIT_OPERATOR_ABORT and run.result.fault is None
    assert_finished_folder(tmp_path / "run", EXIT_OPERATOR_ABORT)


def test_an_exception_leaving_a_step_still_finishes_the_run_folder(tmp_path, monkeypatch):
    """A BaseException out of a step handler (not a fault the executor knows): the arm is
    halted, the exception goes on, and the run folder is finished (failed, exit 3)."""
    from seqrun.steps.registry import HANDLERS

    def broken(step, ex):
        raise SystemExit("a handler gave up")

    monkeypatch.setitem(HANDLERS, "checkpoint", broken)
    with pytest.raises(SystemExit):
        question_run(tmp_path, lambda signals: "y\n")
    report = assert_finished_folder(tmp_path / "run", EXIT_FAULT)
    assert report["status"] == "failed" and report["fault"]["cause"] == "interrupted"
    assert report["fault"]["halt_sent"]


def test_ctrl_c_while_the_yes_answer_prints_ends_the_run_before_the_move(tmp_path):
    """Issue: Ctrl-C while the --yes confirm line was printing escaped the question (a
    KeyboardInterrupt out of the print): a Halt was sent and the report stayed running.
    Now the signal is a request; the run stops before the next step, nothing moves."""
    loaded = load_sequence(ROOT / "sequences" / "totem.yaml")
    arm = load_arm(loaded.arm_path)
    connection = open_connection(force_sim=True, clock=VirtualClock())
    requests = StopRequests()
    signals = RunSignals(requests)

    def confirm_yes(prompt: str) -> bool:   # _ask with --yes: print, no read
        signals.handle(signal.SIGINT)        # arrives in the middle of the print
        return True

    try:
        run = run_sequence(loaded, arm, connection, log_dir=tmp_path / "run",
                           confirm=confirm_yes, requests=requests, html_report=False)
    finally:
        connection.close()
    assert run.result.exit_code == EXIT_OPERATOR_ABORT and run.result.fault is None
    report = assert_finished_folder(tmp_path / "run", EXIT_OPERATOR_ABORT)
    move = next(s for s in report["steps"] if s["kind"] == "move")
    assert move["status"] == "aborted" and move["duration_s"] is None   # never started
    assert not [m for m in read_trace(tmp_path / "run") if _is_halt(m)]
