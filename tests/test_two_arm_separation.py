"""Arm against arm (issue 43, item 3): validation proves the clearance for every timing a
run can take, every control cycle checks the arms from their measured joints and stopping
distances, a faulted arm's neighbour goes on only when its rest of the motion is clear of
where the faulted arm stopped, and the console of several arms refuses a motion into
another arm."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from seqrun.service.arms_check import campaign_has_arms
from twoarmskit import check, copy_example, write

#: A asks the operator inside its branch, then visits the spot B reaches for; B waits a
#: fixed time: on the planned time line (the answer at once) A is gone before B comes,
#: for a late answer they meet.
CONFIRM_INSIDE = """\
name: Confirm inside
description: A asks the operator inside its branch; B reaches over after a fixed wait.
steps:
  - parallel:
      - arm: A
        steps: [include: startup.yaml]
      - arm: B
        steps: [include: startup.yaml]
  - parallel:
      - arm: A
        steps:
          - confirm: Is the target in place?
          - move: {position_mm: [-150, 400, 300], rpy_deg: [0, 0, 90], label: A to the hold pose}
          - move: {pose: totem, label: A back up}
      - arm: B
        steps:
          - move: {pose: totem, label: B up to Totem}
          - wait: 20
          - move: {position_mm: [150, 450, 300], rpy_deg: [0, 0, 90], label: B reaches over}
          - move: {pose: totem, label: B back up}
"""

#: The same, ordered: B reaches over only once A signals it is back up.
ORDERED = CONFIRM_INSIDE.replace(
    "          - move: {pose: totem, label: A back up}\n",
    "          - move: {pose: totem, label: A back up}\n          - signal: A_up\n").replace(
    "          - wait: 20\n", "          - wait_for: {event: A_up, timeout_s: 120}\n")


@pytest.fixture
def campaign(tmp_path, monkeypatch):
    """A copy of the example campaign (arms A and B facing each other, 900 mm apart)."""
    return copy_example(tmp_path, monkeypatch)


# ------------------------------------------------------------------ (a) every timing
def test_a_confirm_that_lets_the_arms_meet_for_a_late_answer_is_refused_there(campaign):
    found = check(write(campaign, "confirm_inside.yaml", CONFIRM_INSIDE), dry_run=False)
    (error,) = found.errors
    lines = CONFIRM_INSIDE.splitlines()
    assert lines[error.line - 1].strip().startswith("- confirm:")
    assert error.column == lines[error.line - 1].index("confirm") + 1
    assert "waits for the operator's answer" in error.message
    assert "order the arms with signal/wait_for" in error.message.lower()
    assert "A.forearm" in error.message and "B." in error.message
    # the planned time line alone (the answer at once) sees them well apart
    (between,) = found.between
    assert between.distance_mm > 100


def test_a_bounded_wait_until_in_position_counts_with_its_timeout(campaign):
    """``wait: {until: in_position, timeout_s: 30}``: at most 30 s, enough for A to be
    over the target when B comes; with 1 s it cannot be."""
    def text(timeout: int) -> str:
        return CONFIRM_INSIDE.replace(
            "          - confirm: Is the target in place?\n",
            f"          - wait: {{until: in_position, timeout_s: {timeout}}}\n")

    found = check(write(campaign, "settles.yaml", text(30)), dry_run=False)
    (error,) = found.errors
    assert "waits until the arm is in position" in error.message
    assert text(30).splitlines()[error.line - 1].strip().startswith("- wait:")
    assert check(write(campaign, "settles_soon.yaml", text(1)), dry_run=False).errors == []


def test_the_same_moves_ordered_with_signal_and_wait_for_validate(campaign):
    found = check(write(campaign, "ordered.yaml", ORDERED), dry_run=False)
    assert found.errors == []


def test_the_shipped_examples_stay_valid_and_refused_as_they_were(campaign):
    good = check(campaign / "sequences" / "hold_and_approach.yaml", dry_run=False)
    assert good.errors == []
    bad = check(campaign / "sequences" / "paths_cross.yaml", dry_run=False)
    assert [e.message.startswith("the arms' paths cross") for e in bad.errors] == [True]


def test_offsets_are_proved_for_every_value_of_the_delays():
    from seqrun.sequence.arm_timing import Stamp, offset_range, rigid

    start = Stamp.zero()
    asked = start.plus(1.0).delayed(0)            # A after a confirm
    waited = start.plus(5.0).later(asked.plus(2.0))  # B waits for A's signal 2 s later
    assert offset_range(asked, start) == (1.0, float("inf"))
    # B ends its wait at max(5, 3 + d): 2 s after A's moment for a late answer, up to
    # 4 s for a quick one
    assert offset_range(waited, asked) == pytest.approx((2.0, 4.0))
    # once B waits for something A signals after the confirm, they move in step
    joined = start.delayed(0).later(start.plus(3.0))
    assert not rigid([(joined, asked)])
    both = asked.later(start)  # the join of a block: the later arm decides
    assert rigid([(both.plus(4.0), asked)])
    assert offset_range(asked, start, {0: 10.0}) == (1.0, 11.0)


# ------------------------------------------------------------------ (b) every cycle
def _lwa3():
    from seqrun.arm.description import load_arm
    from seqrun.shipped import shipped_arm

    return load_arm(shipped_arm("lwa3"))


def _separation(gap_mm: float):
    """Two LWA 3s straight up, ``gap_mm`` between their bases' axes, facing each other."""
    from seqrun.arm.between_arms import base_transform
    from seqrun.service.arm_separation import Separation

    arm = _lwa3()
    return arm, Separation({"A": arm, "B": arm},
                           {"A": base_transform([0, 0, 0], [0, 0, 0]),
                            "B": base_transform([0, gap_mm, 0], [0, 0, 180])})


def test_every_cycle_grows_the_arms_by_their_stopping_distance_and_halts_both():
    from seqrun.errors import RunAborted

    arm, separation = _separation(200.0)  # columns 74 mm apart
    halted: list[tuple[str, str]] = []
    watch_a = separation.watch("A", halt=lambda why, cause: halted.append(("A", cause)))
    watch_b = separation.watch("B", halt=lambda why, cause: halted.append(("B", cause)))
    up = np.zeros(len(arm.joints))
    still = separation.closest("A", separation.report("A", 0.0, up, 0.01))
    assert still is None  # B not measured yet
    watch_b.check(0.0, up, 0.01)
    watch_a.check(0.01, up, 0.01)  # standing: no travel, clear
    (_, _, _, clearance, travel) = separation.closest("A", separation.report("A", 0.02, up,
                                                                             0.01))
    assert travel == 0.0 and clearance > 0
    # A's j2 tips it towards B, fast: at the same measured clearance its braking distance
    # no longer fits, and both are halted
    tipping = up.copy()
    tipping[1] = 0.3  # deg in 10 ms: 30 deg/s, some 100 mm to stop
    with pytest.raises(RunAborted) as caught:
        watch_a.check(0.03, tipping, 0.01)
    assert caught.value.cause == "arms_too_close"
    assert "arms A and B too close" in str(caught.value)
    assert halted == [("B", "arms_too_close")]


def test_the_stopping_travel_is_reaction_plus_braking_times_the_levers():
    from seqrun.arm.between_arms import levers_mm, stopping_travel_mm
    from seqrun.arm.geometry import Geometry

    levers = levers_mm(Geometry(_lwa3()))
    assert np.all(np.diff(levers) <= 1e-9) and levers[0] > levers[-1] > 0
    v = np.zeros(len(levers))
    v[0] = 1.0  # rad/s, braking at 2 rad/s^2 after 0.01 s: 0.01 + 0.25 rad
    travel = stopping_travel_mm(v, np.full(len(levers), 2.0), 0.01, levers)
    assert travel == pytest.approx(0.26 * levers[0])


def test_a_joint_under_a_position_command_travels_no_farther_than_its_target():
    """A module commanded to a position (FRAMP, FSTEP) stops there however long its host
    is silent: the travel of a stalled reading is bounded by the target (plus one more
    cycle's command, and never less than its braking), not grown with the reading's age.
    Without a target (a velocity command) it grows as before."""
    from seqrun.arm.between_arms import levers_mm, stopping_travel_mm
    from seqrun.arm.geometry import Geometry

    levers = levers_mm(Geometry(_lwa3()))
    n = len(levers)
    v, decel = np.zeros(n), np.full(n, 2.0)
    v[0] = 0.5  # rad/s: braking 0.0625 rad
    age = 0.4   # s the host was not run
    free = stopping_travel_mm(v, decel, 0.01 + age, levers)
    assert free == pytest.approx((0.5 * 0.41 + 0.0625) * levers[0])
    gap = np.full(n, np.nan)
    gap[0] = 0.08  # rad to the FRAMP target in force
    held = stopping_travel_mm(v, decel, 0.01 + age, levers, rest_gap_rad=gap,
                              next_command_rad=0.01)
    assert held == pytest.approx(0.09 * levers[0])
    assert held < free / 2
    gap[0] = 0.01  # a target nearer than the braking distance: braking counts
    near = stopping_travel_mm(v, decel, 0.01 + age, levers, rest_gap_rad=gap,
                              next_command_rad=0.0)
    assert near == pytest.approx(0.0625 * levers[0])
    gap[0] = 10.0  # far: never more than the unbounded figure
    assert stopping_travel_mm(v, decel, 0.01 + age, levers, rest_gap_rad=gap,
                              next_command_rad=0.01) == pytest.approx(free)


def test_a_stalled_reading_of_the_other_arm_with_a_near_target_does_not_trip():
    """Issue 42: under load an arm's latest reading grew old (a host stall of 0.4 s) and
    the travel it was grown by grew with it, so a run halted with the arms apart. The
    same reading under a position command to a near target stays clear; without one (a
    velocity command: it could run on) it still trips."""
    from seqrun.errors import RunAborted

    arm, separation = _separation(200.0)
    watch_a = separation.watch("A", halt=lambda why, cause: None)
    watch_b = separation.watch("B", halt=lambda why, cause: None)
    up = np.zeros(len(arm.joints))
    tipping = up.copy()
    tipping[1] = 0.1  # deg in 10 ms: 10 deg/s towards A
    target = np.radians(tipping)
    target[1] += np.radians(0.5)  # half a degree on: where B's FRAMP ends
    holds = np.full(len(arm.joints), np.nan)
    holds[1] = target[1]
    watch_b.check(0.0, up, 0.01, holds_at_rad=holds)
    watch_b.check(0.01, tipping, 0.01, holds_at_rad=holds)
    watch_a.check(0.51, up, 0.01)  # B's reading is 0.5 s old: it stops at its target
    _, separation2 = _separation(200.0)
    watch_a2 = separation2.watch("A", halt=lambda why, cause: None)
    watch_b2 = separation2.watch("B", halt=lambda why, cause: None)
    watch_b2.check(0.0, up, 0.01)
    watch_b2.check(0.01, tipping, 0.01)
    with pytest.raises(RunAborted):
        watch_a2.check(0.51, up, 0.01)  # no target known: 0.5 s more at 10 deg/s


def test_two_readings_a_moment_apart_tell_no_speed():
    """A two-arm run on a loaded host halted with the arms 418 mm apart "within the 845.6
    mm both can still travel": two readings a fraction of a cycle apart made a small
    difference in position a huge speed. Readings are timed when the joints answered, and
    a speed needs them at least half a cycle apart."""
    arm, separation = _separation(900.0)
    up = np.zeros(len(arm.joints))
    nudged = up.copy()
    nudged[1] = 0.05  # deg: the modules' resolution, not motion
    separation.report("A", 0.0, up, 0.01)
    close = separation.report("A", 0.001, nudged, 0.01)
    assert np.all(close.v_rad_s == 0.0)
    apart = separation.report("A", 0.011, up, 0.01)
    assert apart.v_rad_s[1] == pytest.approx(-np.radians(0.05) / 0.01)


def _run_unchecked(campaign: Path, text: str, faults=(), on_fault="halt_all"):
    """Run a sequence's tracks at virtual time on two simulators *without* the check of
    the arms against each other (as if the measured motion left the plan): only the
    per-cycle check stands between them. Returns (outcome, each arm's last joints)."""
    from seqrun.arm.poses import pose_joints_deg
    from seqrun.clock import LockstepClock
    from seqrun.drivers.registry import simulator_positions
    from seqrun.sequence.arm_tracks import load_tracks
    from seqrun.service.arm_context import resolve_contexts
    from seqrun.service.arms_run import run_tracks
    from seqrun.service.connection import open_connection
    from seqrun.service.dryrun import prepare_started

    path = write(campaign, "unchecked.yaml", text)
    project = campaign_has_arms(path)
    contexts = {str(c.arm_id): c for c in resolve_contexts(project=project)}
    tracks = load_tracks(path, project=project,
                         arm_paths={a: c.arm_path for a, c in contexts.items()}).tracks
    arms = {a: c.arm for a, c in contexts.items()}
    shared = LockstepClock()
    views = {a: shared.view() for a in tracks}
    connections = {a: open_connection(force_sim=True, clock=views[a], python_can=False,
                                      sim_positions=simulator_positions(
                                          arms[a], pose_joints_deg(
                                              "park", tracks[a].pose_path
                                              or tracks[a].poses_dir)),
                                      faults=[f for arm, f in faults if arm == a],
                                      default_bitrate=arms[a].can.bitrate)
                   for a in tracks}
    executors = {}

    def attach(arm_id, executor):
        executor.time_limit_s = 120.0
        executors[arm_id] = executor

    try:
        outcome = run_tracks(tracks, arms, connections, dry_run=True, on_fault=on_fault,
                             on_executor=attach, clock_views=views,
                             before_run=lambda a: prepare_started(connections[a], arms[a]),
                             confirm=None, html_report=False)
    finally:
        for connection in connections.values():
            connection.close()
    return outcome, {a: np.radians(e.last.user_deg) for a, e in executors.items()}, contexts


#: Both arms at once to the spot over the target: validation refuses it (the paths
#: cross); run anyway, they would meet.
COLLIDING = """\
name: Into each other
description: A holds over the target while B reaches for the same spot.
steps:
  - parallel:
      - arm: A
        steps:
          - move: {pose: totem, label: A up to Totem}
          - move: {position_mm: [-150, 400, 300], rpy_deg: [0, 0, 90], label: A to the hold pose}
          - wait: 10
      - arm: B
        steps:
          - move: {pose: totem, label: B up to Totem}
          - move: {position_mm: [150, 450, 300], rpy_deg: [0, 0, 90], label: B reaches over}
"""


@pytest.mark.slow
def test_arms_driven_into_each_other_are_both_halted_before_contact(campaign):
    from seqrun.arm.between_arms import between_arms
    from seqrun.arm.geometry import Geometry

    found = check(write(campaign, "colliding.yaml", COLLIDING), started=True, dry_run=False)
    assert found.errors and "paths cross" in found.errors[0].message  # (refused as planned)
    outcome, last, contexts = _run_unchecked(campaign, COLLIDING)
    assert outcome.exit_code == 3
    for arm_id in "AB":
        result = outcome.arms[arm_id].result
        assert result.exit_code == 3, result.message
        assert result.fault["halt_sent"] and result.fault["halt_confirmed"]
    causes = {outcome.arms[a].result.fault["cause"] for a in "AB"}
    assert "arms_too_close" in causes
    text = next(n for n in outcome.notes if "too close" in n)
    assert "arms " in text and " mm from " in text
    # where they stand after the Halts: apart, not in contact
    geometry = Geometry(contexts["A"].arm)
    (smallest, _) = between_arms(("A", geometry, contexts["A"].base_transform()),
                                 ("B", geometry, contexts["B"].base_transform()),
                                 last["A"][None, :], last["B"][None, :])
    assert smallest.distance_mm > 0


# ------------------------------------------------------------------ (c) halt_faulted
#: Timed without events (valid: A is back up long before B comes), A holds over the
#: target for 4 s; B reaches there 20 s later.
A_HOLDS = """\
name: A holds, B comes later
description: A holds over the target for a while, B reaches there later.
steps:
  - parallel:
      - arm: A
        steps:
          - move: {position_mm: [-150, 400, 300], rpy_deg: [0, 0, 90], label: A to the hold pose}
          - wait: 4
          - move: {pose: totem, label: A back up}
      - arm: B
        steps:
          - move: {pose: totem, label: B up to Totem}
          - wait: 20
          - BLAME
"""


def _halt_faulted(campaign: Path) -> None:
    toml = campaign / "seqrun.toml"
    toml.write_text(toml.read_text().replace('# on_fault = "halt_faulted"',
                                             'on_fault = "halt_faulted"'))


def _fault(spec: str):
    from seqrun.sim.faults import parse_fault_spec

    return parse_fault_spec(spec)


@pytest.mark.slow
def test_halt_faulted_halts_the_other_arm_too_when_its_next_step_enters_the_stopped_arm(
        campaign):
    _halt_faulted(campaign)
    text = A_HOLDS.replace("- BLAME", "- move: {position_mm: [150, 450, 300], rpy_deg: "
                                      "[0, 0, 90], label: B reaches over}")
    path = write(campaign, "a_holds.yaml", text)
    # A halted while it holds over the target (its move ends at ~7 s, its wait at ~11 s)
    found = check(path, started=True, faults=[("A", _fault("all:halt@9"))])
    assert found.errors == []
    arms = found.dry_run.outcome.arms
    assert arms["A"].result.exit_code == 3
    assert arms["B"].result.exit_code == 3
    assert arms["B"].halted_for == "A"
    steps = {s.label: s.status for s in arms["B"].result.steps}
    assert steps["B reaches over"] == "pending"  # never started
    assert arms["B"].result.fault["halt_confirmed"]
    assert any("arm B halted too" in n and "where it stopped" in n
               for n in found.dry_run.outcome.notes)


@pytest.mark.slow
def test_halt_faulted_lets_the_other_arm_go_on_when_its_rest_is_clear(campaign):
    _halt_faulted(campaign)
    text = A_HOLDS.replace("- BLAME", "- move: {joints: {j1: -10}, label: B turns away}")
    path = write(campaign, "a_holds_b_away.yaml", text)
    found = check(path, started=True, faults=[("A", _fault("all:halt@9"))])
    assert found.errors == []
    arms = found.dry_run.outcome.arms
    assert arms["A"].result.exit_code == 3
    assert arms["B"].halted_for is None
    steps = {s.label: s.status for s in arms["B"].result.steps}
    assert steps["B turns away"] == "passed"
    assert any("arm B went on" in n for n in found.dry_run.outcome.notes)


# ------------------------------------------------------------------ (d) the console
#: The console's two arms 400 mm apart, both at Park: B turning j1 by -90 degrees swings its
#: folded arm into A.
CLOSE_ARMS = """\
[campaign]
name = "Two arms close"

[arms.A]
arm = "lwa3"

[arms.B]
arm = "lwa3"
base = { position_mm = [0, 400, 0], rpy_deg = [0, 0, 180] }
"""


@pytest.mark.slow  # two arm sessions on simulators in real time
def test_the_console_refuses_a_move_that_places_one_arm_inside_the_other(tmp_path):
    from armsconsolekit import arms_setup
    from consolekit import LOCAL, refused, take_control, wait_for
    from fastapi.testclient import TestClient

    setup = arms_setup(tmp_path, campaign=CLOSE_ARMS)
    try:
        with TestClient(setup.app(token="sesame"), base_url=LOCAL,
                        raise_server_exceptions=False) as client:
            client.headers["Authorization"] = "Bearer sesame"
            take_control(client)
            for path in ("arm-up", "home"):
                assert client.post(f"/api/v1/arms/B/{path}").status_code == 200
            wait_for(lambda: client.get("/api/v1/arms/B/status").json()["activity"]
                     in ("idle", None), 60)
            before = time.perf_counter()
            message = refused(client.post("/api/v1/arms/B/move/joints",
                                          json={"joints": {"j1": -90}}),
                              409, "arm A", "arm B", " mm", "nothing was sent")
            assert message.startswith("move: refused: arm B would come into arm A")
            assert setup.wires["B"].motions(before) == 0  # nothing commanded
            # a move that keeps clear still goes
            r = client.post("/api/v1/arms/B/move/joints", json={"joints": {"j1": 4}})
            assert r.status_code == 200, r.text
    finally:
        setup.close()


def test_a_separation_refuses_a_path_into_the_other_arm_naming_it():
    arm, separation = _separation(700.0)
    park = np.array([0.0, -90.0, 0.0, -120.32, 0.0, 115.74, 0.0])
    separation.stands_at("A", lambda: park)
    out = np.radians([[0.0, -90.0, 0.0, 0.0, 0.0, 0.0, 0.0]])
    reach = np.radians([[-90.0, -90.0, 0.0, 0.0, 0.0, 0.0, 0.0]])
    assert separation.refusal("B", out) is None
    line = separation.refusal("B", reach)
    assert line is not None and "arm B would come into arm A" in line and " mm" in line
    # another arm whose pose cannot be had: refused, never waved through
    separation.stands_at("A", lambda: None)
    assert "where arm A stands is not known" in separation.refusal("B", out)


@pytest.mark.slow  # two served arms, in real time
def test_a_trajectory_for_one_arm_of_several_is_checked_against_the_other_served_arm(
        tmp_path, monkeypatch):
    """What ``seqrun ros --arm-id B`` does with a trajectory (its one call,
    ``attach_other_arms``): arm A is another process's (here: nobody's, read from its
    bus), B's trajectory into it is refused naming A, one clear of it is accepted."""
    import math

    from twoarmskit import quiet, two_served

    from seqrun.errors import Refused
    from seqrun.service.arm_context import resolve_context
    from seqrun.service.arm_separation import attach_other_arms
    from seqrun.service.session import ArmSession
    from seqrun.service.trajectories import JointTrajectory, TrajectoryPoint, check_trajectory

    quiet(tmp_path, monkeypatch)
    first, second = two_served()  # A powered on at Park, B at Totem (straight up)
    try:
        campaign = tmp_path / "dual"
        campaign.mkdir()
        (campaign / "seqrun.toml").write_text(f"""\
[arms.A]
bus = {{ interface = "socketcand", channel = "can0", kwargs = {{ host = "127.0.0.1", port = {first.port} }} }}

[arms.B]
bus = {{ interface = "socketcand", channel = "can0", kwargs = {{ host = "127.0.0.1", port = {second.port} }} }}
base = {{ position_mm = [0, 700, 0], rpy_deg = [0, 0, 180] }}
""")
        monkeypatch.chdir(campaign)
        context = resolve_context(arm_id="B")
        connection = context.open_connection(live=True)
        session = ArmSession(context.arm.with_zero_reference("totem"), connection,
                             project=context.project, arm_id="B")
        try:
            assert attach_other_arms(session, context) is not None
            assert session.arm_up().exit_code == 0
            assert session.home().exit_code == 0
            into = JointTrajectory(("j1", "j2"), (TrajectoryPoint(
                (-math.pi / 2, -math.pi / 2), 10.0),))
            with pytest.raises(Refused) as caught:
                check_trajectory(session, into, folder=tmp_path)
            assert "arm B would come into arm A" in str(caught.value)
            assert " mm" in str(caught.value) and "nothing was sent" in str(caught.value)
            clear = JointTrajectory(("j1",), (TrajectoryPoint((0.1,), 2.0),))
            check, file = check_trajectory(session, clear, folder=tmp_path)
            assert check.valid
        finally:
            session.close()
    finally:
        first.shutdown()
        second.shutdown()


def test_a_jog_is_checked_over_the_stretch_it_can_go_before_its_dead_man():
    from seqrun.errors import Refused
    from seqrun.service.arm_separation import SessionSeparation

    arm, separation = _separation(700.0)
    park = np.array([0.0, -90.0, 0.0, -120.32, 0.0, 115.74, 0.0])
    separation.stands_at("A", lambda: park)
    b = SessionSeparation(separation, "B")
    leaning = np.array([-90.0, -80.0, 0.0, 0.0, 0.0, 0.0, 0.0])  # B reaching towards A
    # j2 on down towards its limit at 10 deg/s, a 0.5 s dead-man: 15 deg ahead is into A
    with pytest.raises(Refused) as caught:
        b.refuse_jog("jog", leaning, 1, -120.0, 10.0, 0.5)
    assert str(caught.value).startswith("jog: refused: arm B would come into arm A")
    # back up, away from A: free
    b.refuse_jog("jog", leaning, 1, 120.0, 10.0, 0.5)
    # from further away the next 15 deg stay clear (every cycle watches the rest)
    b.refuse_jog("jog", np.array([-90.0, -45.0, 0, 0, 0, 0, 0]), 1, -120.0, 10.0, 0.5)
