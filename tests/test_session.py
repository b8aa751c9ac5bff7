"""The arm session (seqrun/service/session.py) on the simulator, at virtual time where the
outcome must be exact: refusals that send nothing, the jog's deadman, halt during a run and
never behind a busy lock or a slow subscriber, questions answered from another thread."""

from __future__ import annotations

import json
import math
import threading
import time
from pathlib import Path

import pytest

from seqrun.arm.description import load_arm
from seqrun.clock import RealClock, VirtualClock
from seqrun.service.connection import open_connection
from seqrun.errors import Refused
from seqrun.powercube.protocol import BROADCAST_ID
from seqrun.service import ArmSession

ROOT = Path(__file__).resolve().parents[1]
ARM = ROOT / "arms" / "lwa3.yaml"
MOTION_COMMANDS = {0x0B}  # SetMotion (FRAMP, FSTEP, TargetVel ...): anything that moves


def open_session(tmp_path: Path, clock=None, **kw) -> ArmSession:
    connection = open_connection(force_sim=True, clock=clock or VirtualClock())
    return ArmSession(load_arm(ARM), connection, status_hz=kw.pop("status_hz", 0),
                      log_root=tmp_path / "runs",
                      poses_dir=kw.pop("poses_dir", ROOT / "poses"), **kw)


class Frames:
    """Every frame the session's client sends (its frame listener), by kind."""

    def __init__(self, session: ArmSession) -> None:
        self.sent: list = []
        session.client.add_frame_listener(self.on_frame)

    def on_frame(self, msg) -> None:
        if not msg.is_rx:
            self.sent.append((time.monotonic(), msg.arbitration_id, bytes(msg.data)))

    def motion(self) -> list:
        return [f for f in self.sent if f[1] != BROADCAST_ID and f[2][:1] == b"\x0b"]

    def halts(self) -> list:
        return [f for f in self.sent if f[1] == BROADCAST_ID and f[2][:1] == b"\x02"]


@pytest.fixture
def session(tmp_path):
    s = open_session(tmp_path)
    s.poll_status()
    assert s.arm_up().ok and s.home().ok
    s.poll_status()
    yield s
    s.close()


def events_of(sub) -> list:
    return sub.drain()


# ---------------------------------------------------------------------- status
def test_status_comes_from_the_latest_measurement_and_never_reads_the_bus(tmp_path):
    s = open_session(tmp_path)
    try:
        frames = Frames(s)
        before = s.status()
        assert before.updated_at is None and before.activity == "idle"
        assert frames.sent == []  # status() alone sends nothing
        polled = s.poll_status()
        assert polled.joints_deg["j2"] == pytest.approx(-90.0)  # Park
        assert polled.end_effector_mm == pytest.approx((365.903, -0.1, 47.921), abs=0.01)
        assert polled.flags["j1"] and not polled.fault
        assert polled.simulator and "SIMULATOR" in polled.bus
        sent = len(frames.sent)
        assert s.status().joints_deg == polled.joints_deg and len(frames.sent) == sent
        assert s.status_dict()["v"] == 1
    finally:
        s.close()


def test_the_idle_poll_runs_by_itself(tmp_path):
    s = open_session(tmp_path, status_hz=20)
    try:
        deadline = time.monotonic() + 5
        while s.status().updated_at is None and time.monotonic() < deadline:
            time.sleep(0.02)
        assert s.status().joints_deg["j4"] == pytest.approx(-120.32)
    finally:
        s.close()


# ---------------------------------------------------------------------- refusals
BAD_MOVES = [
    ({"j9": 10}, "unknown joint"),
    ({"j1": float("nan")}, "not a finite number"),
    ({"j1": "ten"}, "not a number"),
    ({"j1": 200}, "outside its limits"),
    ({"j3": 10}, "locked"),
    ({}, "at least one joint"),
]


@pytest.mark.parametrize("targets,why", BAD_MOVES)
def test_a_bad_joint_target_is_refused_and_nothing_moves(session, targets, why):
    frames = Frames(session)
    with pytest.raises(Refused, match=why):
        session.move_to_joints(targets)
    assert frames.motion() == [] and session.activity is None


def test_refusals_for_poses_velocities_jogs_and_answers(session):
    frames = Frames(session)
    cases = [
        (lambda: session.move_to_pose("nowhere"), "nowhere"),
        (lambda: session.move_to_pose("totem", velocity_scale=2), r"\(0, 1\]"),
        (lambda: session.set_move_velocities({"j1": -1}), "positive"),
        (lambda: session.set_move_velocities({"j1": 1e6}), "above its limit"),
        (lambda: session.set_move_velocities({"j1": math.inf}), "finite"),
        (lambda: session.set_move_velocities({"jx": 1}), "unknown joint"),
        (lambda: session.jog("j1", 0), "not be 0"),
        (lambda: session.jog("j1", 1.5), r"\[-1, 1\]"),
        (lambda: session.jog("j1", float("nan")), "finite"),
        (lambda: session.jog("j3", 0.5), "locked"),
        (lambda: session.jog("j9", 0.5), "unknown joint"),
        # Park: j4 stands beyond its lower limit, the tool 48 mm above the desk.
        (lambda: session.jog("j4", -0.5), "lower limit"),
        (lambda: session.answer("q99", True), "no open question"),
        (lambda: session.pause(), "no sequence is running"),
        (lambda: session.step(), "no step is waiting"),
        (lambda: session.save_pose("bad name!"), "not a pose name"),
        (lambda: session.run_sequence(ROOT / "sequences" / "nothere.yaml"), "nothere"),
        (lambda: session.run_sequence(ROOT / "sequences" / "opsafe.yaml", speed=0), r"\(0, 1\]"),
    ]
    for call, why in cases:
        with pytest.raises(Refused, match=why):
            call()
    assert frames.motion() == [] and session.activity is None


def test_booleans_and_texts_are_not_numbers(session):
    """Every face hands typed values on: True is not 1 and "12" is not 12 (issue 24)."""
    session.arm_up()
    session.home()
    frames = Frames(session)
    for call in (lambda: session.move_to_joints({"j1": True}),
                 lambda: session.move_to_joints({"j1": "12"}),
                 lambda: session.move_to_joints({"j1": " 14 "}),
                 lambda: session.move_to_pose("totem", velocity_scale=True),
                 lambda: session.set_move_velocities({"j1": True}),
                 lambda: session.jog("j1", True),
                 lambda: session.run_sequence(ROOT / "sequences" / "opsafe.yaml", speed=True)):
        with pytest.raises(Refused, match="is not a number"):
            call()
    assert frames.motion() == [] and session.activity is None


def test_an_invalid_sequence_is_refused_with_its_location(session, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: bad\ndescription: x\nsteps:\n  - move: {joints: {j1: 400}}\n")
    with pytest.raises(Refused, match=r"bad.yaml:4:\d+: .*j1"):
        session.run_sequence(bad)


def test_a_second_activity_is_refused_while_one_runs(session):
    frames = Frames(session)
    sub = session.subscribe(maxsize=100_000)
    move = session.move_to_joints({"j1": 60})
    with pytest.raises(Refused, match="under way"):
        session.move_to_joints({"j1": -60})
    with pytest.raises(Refused, match="under way"):
        session.reset()
    assert move.wait(60).ok
    planned = [e for e in events_of(sub) if e.type == "move_planned"]
    assert len(planned) == 1 and planned[0].target_deg[0] == pytest.approx(60)
    assert frames.motion()


def test_a_move_while_halted_is_refused_until_an_explicit_reset(session):
    assert session.halt("test").confirmed
    assert session.status().activity == "halted"
    frames = Frames(session)
    for call in (lambda: session.move_to_joints({"j1": 10}), lambda: session.jog("j1", 0.5),
                 lambda: session.move_to_pose("totem"), lambda: session.home()):
        with pytest.raises(Refused, match="halted"):
            call()
    assert frames.motion() == []
    assert session.reset().confirmed
    session.poll_status()
    assert session.status().activity == "idle"
    assert session.move_to_joints({"j1": 5}).wait(60).ok


def test_moves_use_the_console_velocities(session):
    session.set_move_velocities({"j1": 4.0})
    sub = session.subscribe()
    assert session.move_to_joints({"j1": 8}).wait(60).ok
    planned = next(e for e in events_of(sub) if e.type == "move_planned")
    keep = 1 - session.arm.control.tracking_reserve
    assert planned.velocity_limit_deg_s[0] == pytest.approx(4.0 * keep, abs=1e-3)
    # 8 degrees at 4 deg/s (less the tracking reserve) take at least two seconds.
    assert planned.duration_s >= 2.0
    assert session.status().joints_deg["j1"] == pytest.approx(8, abs=0.1)


def test_a_move_to_a_pose_goes_through_the_validator_and_executor(session):
    sub = session.subscribe(maxsize=100_000)
    result = session.move_to_pose("totem").wait(120)
    assert result.ok and result.run_result.steps[0].kind == "move"
    kinds = [e.type for e in events_of(sub)]
    assert kinds.index("preflight") < kinds.index("move_planned") < kinds.index("run_finished")
    assert "setpoint" in kinds and "measurement" in kinds
    assert all(abs(v) < 0.1 for v in session.status().joints_deg.values())


# ---------------------------------------------------------------------- jog
PARK = [0.0, -90.0, 0.0, -120.32, 0.0, 115.74, 0.0]


def test_a_jog_ends_short_of_the_workspace_guard_and_is_refused_at_it():
    import numpy as np

    from seqrun.service.jog import GUARD_MARGIN_MM, plan_jog

    arm = load_arm(ARM)
    down = plan_jog(arm, "j2", -0.5, np.array(PARK), 10.0)
    assert "desk" in down.why_end and -100 < down.end_deg < -90
    assert down.velocity_deg_s == pytest.approx(5.0)
    up = plan_jog(arm, "j2", 0.5, np.array(PARK), 10.0)
    assert up.why_end == "joint limit" and up.end_deg == pytest.approx(119.0)
    at_guard = np.array(PARK)
    at_guard[1] = down.end_deg - 0.25  # within the guard's margin
    with pytest.raises(Refused, match=f"within {GUARD_MARGIN_MM:g} mm of its workspace guard"):
        plan_jog(arm, "j2", -0.5, at_guard, 10.0)
    below = np.array(PARK)
    below[1] = -100.0  # the tool below the desk's plane
    with pytest.raises(Refused, match="outside its workspace guard 'desk'"):
        plan_jog(arm, "j1", 0.5, below, 10.0)


def test_a_jog_not_renewed_stops_after_the_deadman_time(session):
    sub = session.subscribe(maxsize=100_000)
    start = session.status().joints_deg["j1"]
    result = session.jog("j1", 0.5).wait(60)
    assert result.ok and "not renewed within 200 ms" in result.message
    events = events_of(sub)
    begun = next(e for e in events if e.type == "jog_started")
    stop = next(e for e in events if e.type == "controlled_stop")
    # The deadman (200 ms) is checked every control cycle (10 ms).
    assert 0.2 <= stop.clock_s - begun.clock_s <= 0.2 + 2 * 0.01 + 1e-9
    assert [e.type for e in events].count("abort_requested") == 1
    moved = session.status().joints_deg["j1"] - start
    assert 0 < moved < 5  # a little, in the commanded direction, then held
    assert all(v == 0.0 for v in session.status().velocities_deg_s.values())
    # Nothing restarts by itself: no motion command after the stop ended.
    assert next(i for i, e in enumerate(events) if e.type == "holding") > \
        max(i for i, e in enumerate(events) if e.type == "setpoint")


def test_a_renewed_jog_keeps_moving_and_stops_when_released(tmp_path):
    s = open_session(tmp_path, clock=RealClock())
    try:
        s.poll_status()
        assert s.arm_up().ok and s.home().ok
        s.poll_status()
        t0 = time.monotonic()
        activity = s.jog("j1", 0.5)
        while time.monotonic() - t0 < 0.8:
            assert s.jog("j1", 0.4) is activity  # renews (same joint, same direction)
            with pytest.raises(Refused, match="another jog"):
                s.jog("j1", -0.5)
            time.sleep(0.05)
        released = time.monotonic()
        result = activity.wait(10)
        assert result.ok and "released" in result.message
        assert time.monotonic() - released < 2.0
        assert s.status().joints_deg["j1"] > 1.0
    finally:
        s.close()


def test_jog_stop_after_the_deadman_is_no_second_abort(session):
    """A release that comes after the deadman fired must not be taken for a second abort
    (the executor halts on a second one): one abort, a controlled stop, no Halt."""
    sub = session.subscribe(maxsize=100_000)
    activity = session.jog("j1", 0.5)
    activity.wait(60)
    assert session.jog_stop() is None  # over already
    session.abort("late release")  # nothing runs: no effect
    types = [e.type for e in events_of(sub)]
    assert types.count("abort_requested") == 1 and "halt_requested" not in types
    assert "fault" not in types and session.status().activity == "idle"


def test_a_jog_stopped_at_once_is_a_controlled_stop(tmp_path):
    s = open_session(tmp_path, clock=RealClock())
    try:
        s.poll_status()
        assert s.arm_up().ok and s.home().ok
        s.poll_status()
        sub = s.subscribe(maxsize=100_000)
        s.jog("j1", 0.5)
        time.sleep(0.1)
        s.jog("j1", 0.5)
        result = s.jog_stop()
        assert result is not None and result.ok and "jog stopped" in result.message
        types = [e.type for e in sub.drain()]
        assert types.count("abort_requested") == 1 and "controlled_stop" in types
        assert "halt_requested" not in types
    finally:
        s.close()


# ---------------------------------------------------------------------- halt
def test_halt_during_a_run_stops_it_and_is_confirmed(session):
    sub = session.subscribe(maxsize=100_000)
    run = session.run_sequence(ROOT / "sequences" / "totem.yaml", assume_yes=True,
                               html_report=False)
    while True:  # wait for the long move to stream
        event = sub.get(timeout=30)
        assert event is not None
        if event.type == "setpoint":
            break
    assert session.status().activity == "running"
    confirmation = session.halt("STOP from a test")
    assert confirmation.sent and confirmation.confirmed
    result = run.wait(30)
    assert result.exit_code == 130 and result.run_dir is not None
    assert (result.run_dir / "events.jsonl.gz").exists()
    assert session.status().activity == "halted"
    with pytest.raises(Refused, match="halted"):
        session.move_to_joints({"j1": 1})


def test_the_status_says_halted_once_the_halt_is_read_back_not_when_the_run_ends(session):
    """Issue 24.7: the HALTED badge came 1.3-1.8 s after the STOP, when the run had written
    its report. The status is "halted" from the moment the modules were read back HALTED,
    before any face hears of it."""
    sub = session.subscribe(maxsize=100_000)
    seen: list[str] = []

    def at_read_back(event):  # a face: what does the status say when it hears of it?
        if event.type == "halt_confirmed":
            seen.append(session.status().activity)

    session.events.add_listener(at_read_back, "a face")
    run = session.run_sequence(ROOT / "sequences" / "totem.yaml", assume_yes=True,
                               html_report=True)  # (a report to write after the Halt)
    while (event := sub.get(timeout=30)) is not None and event.type != "setpoint":
        pass
    threading.Thread(target=session.halt, args=("STOP from a test",)).start()
    while (event := sub.get(timeout=30)) is not None and event.type != "halt_confirmed":
        pass
    assert wait_until(lambda: seen) == ["halted"]
    assert run.wait(60).exit_code == 130


def test_a_refused_pose_names_its_pose_file_not_the_session_s(tmp_path):
    """A pose whose j4 lies beyond its limit: the refusal says where that is."""
    from projecttree import make_project
    from seqrun.sequence.project import open_project

    root = make_project(tmp_path / "campaign")
    park = root / "poses" / "park.yaml"
    park.write_text(park.read_text(encoding="utf-8").replace("j4: -120.32", "j4: -121"),
                    encoding="utf-8")
    project = open_project(root)
    s = open_session(tmp_path, project=project, poses_dir=tuple(project.pose_path))
    try:
        s.poll_status()
        assert s.arm_up().ok and s.home().ok
        with pytest.raises(Refused) as refused:
            s.move_to_pose("park")
    finally:
        s.close()
    message = str(refused.value)
    assert "park.yaml:14:7: j4 -121° is outside its limits" in message
    assert "seqrun-session" not in message and "used at" not in message


def wait_until(predicate, timeout: float = 10.0):
    deadline = time.monotonic() + timeout
    while not (value := predicate()):
        assert time.monotonic() < deadline, "not within the time"
        time.sleep(0.01)
    return value


def test_halt_is_not_held_up_by_a_busy_client_or_a_slow_subscriber(session):
    frames = Frames(session)
    session.events.add_listener(lambda event: time.sleep(1.0), "sleeps 1 s per event")
    release = threading.Event()
    held = threading.Event()

    def hold_the_client() -> None:  # another thread in the middle of a long exchange
        with session.client._lock:
            held.set()
            release.wait(5)

    threading.Thread(target=hold_the_client, daemon=True).start()
    assert held.wait(5)
    done = {}
    t0 = time.monotonic()
    caller = threading.Thread(target=lambda: done.setdefault("r", session.halt("STOP")))
    caller.start()
    deadline = time.monotonic() + 2
    while not frames.halts() and time.monotonic() < deadline:
        time.sleep(0.001)
    assert frames.halts(), "no Halt frame while the client was busy"
    assert frames.halts()[0][0] - t0 < 0.1
    release.set()  # the confirmation reads wait for the exchange, the broadcast did not
    caller.join(10)
    assert done["r"].confirmed


# ---------------------------------------------------------------------- questions
def answer_every_question(session, yes: bool) -> threading.Thread:
    sub = session.subscribe()

    def answer() -> None:
        for event in sub:
            if event.type == "confirm_requested":
                session.answer(event.question_id, yes)
            if event.type == "activity_finished":
                return

    thread = threading.Thread(target=answer, daemon=True)
    thread.start()
    return thread


def test_a_confirm_step_is_answered_from_another_thread(session):
    answering = answer_every_question(session, True)
    result = session.run_sequence(ROOT / "sequences" / "totem.yaml", html_report=False).wait(120)
    answering.join(5)
    assert result.ok, result.message
    assert result.run_result.steps[-1].status == "passed"


def test_a_declined_question_is_an_operator_abort(session):
    answering = answer_every_question(session, False)
    result = session.run_sequence(ROOT / "sequences" / "totem.yaml", html_report=False).wait(120)
    answering.join(5)
    assert result.exit_code == 130 and "declined" in result.message


def test_step_mode_waits_for_step_and_abort_withdraws_the_question(session):
    sub = session.subscribe(maxsize=100_000)
    run = session.run_sequence(ROOT / "sequences" / "totem.yaml", step_mode=True,
                               assume_yes=True, html_report=False)
    asked = []
    while len(asked) < 2:
        event = sub.get(timeout=30)
        assert event is not None
        if event.type == "confirm_requested":
            asked.append(event)
            if len(asked) == 1:
                session.step()
    assert "step 2/" in asked[1].text
    session.abort("test")
    result = run.wait(30)
    assert result.exit_code == 130 and session.pending_questions() == {}


# ---------------------------------------------------------------------- poses
def test_save_pose_writes_the_measured_joints(session, tmp_path):
    from seqrun.arm.poses import load_pose

    assert session.move_to_joints({"j1": 12.5}).wait(60).ok
    session.poll_status()
    session.project = None
    path = session.save_pose("here", description="test")
    try:
        assert load_pose(path).joints_deg["j1"] == pytest.approx(12.5, abs=0.05)
        with pytest.raises(Refused, match="exists"):
            session.save_pose("here")
    finally:
        path.unlink()


def test_a_run_on_the_callers_thread_is_the_sessions_activity(session, tmp_path):
    """``seqrun run`` runs through ``run_loaded``: while it runs, status says so and a
    second activity is refused; a STOP from another thread (the control socket) halts it."""
    from seqrun.sequence.loader import load_sequence

    loaded = load_sequence(ROOT / "sequences" / "totem.yaml")
    seen = {}

    def confirm(prompt: str) -> bool:
        seen["activity"] = session.status().activity
        with pytest.raises(Refused, match="under way"):
            session.move_to_joints({"j1": 1})
        seen["thread"] = threading.Thread(
            target=lambda: seen.setdefault("halt", session.halt("remote STOP")), daemon=True)
        seen["thread"].start()
        time.sleep(0.2)
        return True

    outcome = session.run_loaded(loaded, log_dir=tmp_path / "run", confirm=confirm,
                                 html_report=False)
    assert seen["activity"] == "running"
    assert outcome.result.exit_code == 130
    seen["thread"].join(10)
    assert seen["halt"].confirmed and session.activity is None


def test_idle_hooks_run_on_the_loop_thread_of_every_activity_until_removed(session, tmp_path):
    """A face draws between cycles through the session (the live view of ``seqrun run``):
    its hook gets the slack on the thread that runs the loop (the caller's for
    ``run_loaded``, the worker's for a move), and nothing after it is removed."""
    from seqrun.sequence.loader import load_sequence

    calls: list[tuple[str, float]] = []

    def hook(slack: float) -> None:
        calls.append((threading.current_thread().name, slack))

    session.add_idle_hook(hook)
    loaded = load_sequence(ROOT / "sequences" / "totem.yaml")
    outcome = session.run_loaded(loaded, log_dir=tmp_path / "run", confirm=lambda p: True,
                                 html_report=False)
    assert outcome.result.exit_code == 0, outcome.result.message
    here = threading.current_thread().name
    assert len(calls) > 10 and {name for name, _ in calls} == {here}
    assert all(slack > 0 for _, slack in calls)
    n = len(calls)
    assert session.move_to_joints({"j1": 5}).wait(120).ok
    assert len(calls) > n and calls[-1][0] != here
    session.remove_idle_hook(hook)
    n = len(calls)
    assert session.move_to_joints({"j1": 0}).wait(120).ok
    assert len(calls) == n


def test_the_deadman_fires_in_real_time_even_when_the_loop_has_no_idle_time():
    """A loop that is always late never calls its idle hooks; the deadman's own
    supervisor thread still posts the abort, once."""
    from seqrun.service.jog import Deadman

    posted = []
    deadman = Deadman(RealClock(), 0.2)
    deadman.arm(posted.append)  # the idle hook it returns is never called here
    try:
        time.sleep(0.6)
        assert len(posted) == 1 and "200 ms" in posted[0]
        deadman.release("late release")
        assert len(posted) == 1
    finally:
        deadman.disarm()


def test_a_run_started_through_the_session_leaves_its_record(tmp_path):
    """The console's runs keep what ran as seqrun run does: record.json and inputs/, from
    the bytes validated (an edit to the file after the start changes neither)."""
    sequence = tmp_path / "short.yaml"
    text = ("name: Short\ndescription: one move\n"
            "steps:\n  - move: {joints: {j1: 5}, label: A little}\n")
    sequence.write_text(text)
    s = open_session(tmp_path, arm_path=ARM)
    try:
        s.poll_status()
        assert s.arm_up().ok and s.home().ok
        s.poll_status()
        run = s.run_sequence(sequence, html_report=False)
        sequence.write_text(text.replace("j1: 5", "j1: 50"))  # edited while it runs
        result = run.wait(120)
    finally:
        s.close()
    assert result.ok, result.message
    record = json.loads((result.run_dir / "record.json").read_text())
    kept = {Path(i["path"]).name: result.run_dir / i["copy"] for i in record["inputs"]}
    assert set(kept) == {"short.yaml", "lwa3.yaml"}
    assert kept["short.yaml"].read_text() == text
    assert kept["lwa3.yaml"].read_bytes() == ARM.read_bytes()
