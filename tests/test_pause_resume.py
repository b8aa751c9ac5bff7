"""Pause and Resume of a running sequence (issue 40, item 5): a Pause lets the step under
way finish, then the run holds before the next step, the arm at rest (nothing commanded);
a Resume first validates the rest of the sequence from the arm's measured pose, as the run
does at its start, and is refused with the reason (the run stays paused) when that fails;
STOP or abort while paused ends the run as an operator abort (exit 130). At virtual time."""

from __future__ import annotations

import math
import shutil
import threading
import time
from pathlib import Path

import can
import pytest

from projecttree import ROOT
from runfolder import RunFolder
from seqrun.arm.description import load_arm
from seqrun.clock import VirtualClock
from seqrun.errors import Refused
from seqrun.results import EXIT_OK, EXIT_OPERATOR_ABORT
from seqrun.service import ArmSession
from seqrun.service.connection import open_connection
from simrun import run_on_sim

#: j1 to 20°, then 100° further (relative), then back: with j1 pushed to 100° while
#: paused, the second step's target (200°) is outside j1's limits (±180°).
STEPS = """name: pause
steps:
  - move: {joints: {j1: 20}, label: first}
  - move: {joints: {j1: 100}, relative: true, label: second}
  - move: {joints: {j1: 0}, label: third}
"""


def campaign(tmp_path: Path) -> Path:
    root = tmp_path / "campaign"
    for folder in ("sequences", "arms", "poses"):
        shutil.copytree(ROOT / folder, root / folder)
    (root / "sequences" / "pause.yaml").write_text(STEPS)
    return root


def is_motion(msg: can.Message) -> bool:
    return (0x0E1 <= msg.arbitration_id <= 0x0FF and not msg.is_rx
            and msg.data[:1] == b"\x0b")


def in_thread(call) -> None:
    """``call`` from another thread (as the console's would come), waited for."""
    worker = threading.Thread(target=call)
    worker.start()
    worker.join()


def pause_during_step_1(state: dict, on_paused_cycle):
    """An executor hook: Pause while step 1 moves; ``on_paused_cycle(executor, n)`` on the
    n-th measurement the paused run reads."""
    def hook(executor):
        def listener(event):
            kind = event["type"]
            if kind == "setpoint" and event.get("step") == 1 and "asked" not in state:
                state["asked"] = True
                in_thread(executor.pause)
            elif kind == "run_paused":
                state["cycles"] = 0
            elif kind == "run_resumed":
                state.pop("cycles", None)
            elif kind == "measurement" and "cycles" in state:
                state["cycles"] += 1
                on_paused_cycle(executor, state["cycles"])
        executor.listeners.append(listener)
    return hook


def test_pause_holds_between_steps_and_resume_checks_the_measured_pose(tmp_path):
    state: dict = {}
    asks: list = []

    def on_paused_cycle(executor, n):
        sim = state["sim"]
        if n == 20:   # pushed while paused: the next step would leave j1's limits
            sim.set_positions({1: math.radians(100)})
            asks.append(executor.resume())
        elif n == 40 and len(asks) == 1:
            sim.set_positions({1: math.radians(20)})   # back where step 1 left it
            asks.append(executor.resume())

    outcome, sim, _ = run_on_sim(
        "pause", tmp_path, root=campaign(tmp_path), started=True,
        before=lambda connection: state.update(sim=connection.bus.arm),
        on_executor=pause_during_step_1(state, on_paused_cycle))
    assert outcome.result.exit_code == EXIT_OK, outcome.result.message
    folder = RunFolder(outcome.log_dir)
    events = [e for e in folder.events() if e["type"] not in ("setpoint", "measurement")]
    kinds = [e["type"] for e in events]
    # The step under way finished (no controlled stop), then the run held before step 2.
    assert "controlled_stop" not in kinds
    order = ["pause_requested", "step_finished", "run_paused", "resume_refused",
             "run_resumed", "step_started"]
    at = [kinds.index(order[0])]
    for kind in order[1:]:
        at.append(kinds.index(kind, at[-1]))
    assert events[at[1]]["step"] == 1 and events[at[1]]["status"] == "passed"
    paused, refused, resumed, started = (events[i] for i in at[2:])
    assert paused["step"] == refused["step"] == resumed["step"] == started["step"] == 2
    assert paused["location"].endswith("pause.yaml:4:5") and paused["label"] == "second"
    # The refusal names the step's line and why; the run stayed paused until the second.
    assert "pause.yaml:4:" in refused["reason"] and "200" in refused["reason"]
    assert "outside its limits" in refused["reason"]
    assert all(ask.wait(0) for ask in asks)   # each one answered
    assert asks[0].refused == refused["reason"] and asks[1].refused is None
    assert kinds.count("run_paused") == 1 and kinds.count("resume_refused") == 1
    # Each Resume validated the rest from a fresh reading of the arm (a preflight each).
    preflights = [e for e in events if e["type"] == "preflight"]
    assert [p["start_deg"][0] for p in preflights] == [0.0, 100.0, 20.0]
    # Nothing moved while paused: no motion command between run_paused and run_resumed.
    start = next(e for e in folder.events("run_started"))["clock_s"]
    sent = [m.timestamp - start for m in folder.trace() if is_motion(m)]
    held = [t for t in sent if paused["t"] < t < resumed["t"]]
    assert held == [] and any(t > resumed["t"] for t in sent)
    # Steps 2 and 3 ran after the Resume: the arm ends at j1 = 0.
    steps = folder.report()["steps"]
    assert [s["status"] for s in steps] == ["passed"] * 3
    # The report keeps the hold with the step it came before (not in its duration).
    assert steps[1]["paused_s"] == pytest.approx(resumed["t"] - paused["t"], abs=1e-3)
    assert steps[1]["resumes_refused"] == 1
    assert "paused_s" not in steps[0] and "paused_s" not in steps[2]
    assert steps[1]["duration_s"] < 5.0
    assert math.degrees(sim.module(1).position()) == pytest.approx(0.0, abs=0.3)


@pytest.mark.parametrize("stop", ["halt", "abort"])
def test_stop_or_abort_while_paused_is_an_operator_abort(tmp_path, stop):
    state: dict = {}
    asks: list = []

    def on_paused_cycle(executor, n):
        if n == 5:
            state["sim"].set_positions({1: math.radians(100)})
            asks.append(executor.resume())   # refused: the run stays paused
        if n == 30:
            in_thread(lambda: executor.halt("STOP from a test") if stop == "halt"
                      else executor.abort("abort from a test"))

    outcome, _, _ = run_on_sim(
        "pause", tmp_path, root=campaign(tmp_path), started=True,
        before=lambda connection: state.update(sim=connection.bus.arm),
        on_executor=pause_during_step_1(state, on_paused_cycle))
    result = outcome.result
    assert result.exit_code == EXIT_OPERATOR_ABORT, result.message
    assert asks[0].wait(0) and asks[0].refused is not None
    kinds = [e["type"] for e in RunFolder(outcome.log_dir).events()]
    assert "run_paused" in kinds and "run_resumed" not in kinds
    assert kinds.count("step_started") == 1    # step 2 never started
    report = RunFolder(outcome.log_dir).report()
    assert [s["status"] for s in report["steps"]][:1] == ["passed"]
    assert report["exit_code"] == EXIT_OPERATOR_ABORT


def test_a_resume_before_the_pause_is_taken_withdraws_it(tmp_path):
    asks: list = []

    def hook(executor):
        def listener(event):
            if event["type"] == "setpoint" and event.get("step") == 1 and not asks:
                in_thread(executor.pause)
                asks.append(executor.resume())   # the step still runs: nothing to check
        executor.listeners.append(listener)

    outcome, _, _ = run_on_sim("pause", tmp_path, root=campaign(tmp_path), started=True,
                               on_executor=hook)
    assert outcome.result.exit_code == EXIT_OK, outcome.result.message
    assert asks[0].wait(0) and asks[0].refused is None
    kinds = [e["type"] for e in RunFolder(outcome.log_dir).events()]
    assert "pause_requested" in kinds and "run_paused" not in kinds


# ---------------------------------------------------------------------- the session
def wait_for_status(session, ok, timeout_s: float = 30.0):
    """The session's status once ``ok`` holds (its status follows the events on a thread
    of its own)."""
    deadline = time.monotonic() + timeout_s
    while not ok(status := session.status()):
        assert time.monotonic() < deadline, status
        time.sleep(0.01)
    return status


def test_the_session_pauses_refuses_jogs_and_a_resume_from_a_moved_pose(tmp_path):
    """Through the service layer the console uses: the status says where the run holds,
    a jog or move while paused is refused with one line, a Resume from a pose the rest
    does not hold from is Refused with the reason."""
    root = campaign(tmp_path)
    connection = open_connection(force_sim=True, clock=VirtualClock())
    session = ArmSession(load_arm(root / "arms" / "lwa3.yaml"), connection, status_hz=0,
                         log_root=tmp_path / "runs", poses_dir=root / "poses")
    try:
        session.poll_status()
        assert session.arm_up().ok and session.home().ok
        sim = connection.bus.arm
        sub = session.subscribe(maxsize=1_000_000)
        run = session.run_sequence(root / "sequences" / "pause.yaml", html_report=False)
        while (event := sub.get(timeout=30)) is not None and event.type != "step_started":
            pass
        session.pause()
        while (event := sub.get(timeout=30)) is not None and event.type != "run_paused":
            pass
        assert event is not None and event.step == 2
        status = wait_for_status(session, lambda s: s.activity == "paused")
        assert status.run is not None and status.run.pause == "paused"
        assert status.run.paused_before == f"Paused before step 2 ({event.location})"
        for jog_or_move in (lambda: session.jog("j1", 0.5),
                            lambda: session.move_to_joints({"j1": 30})):
            with pytest.raises(Refused, match="Paused before step 2.*while a run is paused"):
                jog_or_move()
        sim.set_positions({1: math.radians(100)})
        with pytest.raises(Refused, match=r"resume refused: .*pause.yaml:4:\d+: .*200"):
            session.resume()
        assert session.status().activity == "paused"
        sim.set_positions({1: math.radians(20)})
        session.resume()
        result = run.wait(120)
        assert result.ok, result.message
        assert session.status().run is None
        assert [e.type for e in sub.drain() if e.type in ("resume_refused", "run_resumed")] \
            == ["resume_refused", "run_resumed"]
    finally:
        session.close()


def test_pause_and_resume_need_a_run(tmp_path):
    connection = open_connection(force_sim=True, clock=VirtualClock())
    session = ArmSession(load_arm(ROOT / "arms" / "lwa3.yaml"), connection, status_hz=0,
                         log_root=tmp_path / "runs", poses_dir=ROOT / "poses")
    try:
        for call in (session.pause, session.resume):
            with pytest.raises(Refused, match="no sequence is running"):
                call()
    finally:
        session.close()
