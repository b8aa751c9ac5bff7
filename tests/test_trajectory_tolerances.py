"""A trajectory's path and goal tolerances, as joint_trajectory_controller's (issue 41.1):
the ``move_trajectory`` step's keys (checked at file:line:col), the run at virtual time on the
simulator (a stuck module trips the path tolerance before the arm file's own bound; a goal
tolerance tighter than the arm settles fails naming the joint), ROS's ``constraints.*``
parameters and a goal's fields (seqrun/arm/trajectory_tolerances.py)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from projecttree import write_sequence
from runfolder import RunFolder
from seqrun.arm.description import load_arm
from seqrun.arm.trajectory_tolerances import (TrajectoryTolerances, from_parameters, override,
                                              problems)
from simrun import run_on_sim
from test_ros_trajectory import session  # noqa: F401  (an armed, homed session at virtual time)

ROOT = Path(__file__).resolve().parents[1]
ARM = ROOT / "arms" / "lwa3.yaml"
UP = "- reset\n- home\n- set_limits\n"  # lines 4-6: the trajectory is on line 7
#: j1 from Park (0°) by 30° in 3 s, through 30 points.
RISE = "t,j1\n" + "".join(f"{0.1 * i:.1f},{i:.1f}\n" for i in range(1, 31))


def trajectory_sequence(project: Path, keys: str = "", name: str = "traj.yaml") -> Path:
    (project / "sequences" / "rise.csv").parent.mkdir(parents=True, exist_ok=True)
    (project / "sequences" / "rise.csv").write_text(RISE, encoding="utf-8")
    return write_sequence(project, UP + "- move_trajectory: {file: rise.csv%s}\n" % keys, name)


def test_a_path_tolerance_stops_a_stuck_joint_before_the_arm_files_bound(tmp_path, project):
    trajectory_sequence(project, name="plain.yaml")
    trajectory_sequence(project, ", path_tolerance_deg: {j1: 1.0}", "tight.yaml")
    plain = run_on_sim("plain", tmp_path / "a", root=project, faults=["1:stuck@0.5"])
    tight = run_on_sim("tight", tmp_path / "b", root=project, faults=["1:stuck@0.5"])
    assert plain.outcome.result.fault["cause"] == "following_error"
    result = tight.outcome.result
    assert result.exit_code == 3 and result.fault["cause"] == "path_tolerance"
    assert result.message.startswith("PATH_TOLERANCE_VIOLATED: j1 (module 1) 1.")
    assert "from its setpoint at t=" in result.message and "(path tolerance 1°)" in result.message
    # stopped first (a controlled stop streamed), then the run's Halt, confirmed
    log = RunFolder(tight.outcome.log_dir).events()
    kinds = [e["type"] for e in log]
    assert "controlled_stop" in kinds and kinds.index("controlled_stop") < kinds.index("fault")
    assert result.fault["halt_confirmed"] is True
    # stopped sooner than the arm file's 4° bound halted the same fault
    stopped_t = next(e["t"] for e in log if e["type"] == "controlled_stop")
    assert stopped_t < plain.outcome.result.steps[3].finished - 0.1


def test_a_path_tolerance_that_holds_lets_the_trajectory_run(tmp_path, project):
    trajectory_sequence(project, ", path_tolerance_deg: {j1: 1.0}, goal_tolerance_deg: "
                                 "{j1: 0.05}, goal_time_s: 1.0")
    sim = run_on_sim("traj", tmp_path, root=project)
    assert sim.outcome.result.exit_code == 0, sim.outcome.result.message


def test_a_goal_tolerance_not_met_in_goal_time_fails_naming_the_joint(tmp_path, project):
    """j1 stops short: stuck 0.1 s before the end (within the arm file's following bound,
    about 1° from its last point)."""
    trajectory_sequence(project, ", goal_tolerance_deg: {j1: 0.5}, goal_time_s: 0.2")
    result = run_on_sim("traj", tmp_path, root=project,
                        faults=["1:stuck@2.9"]).outcome.result
    assert result.exit_code == 3 and result.fault["cause"] == "goal_tolerance", result.message
    assert result.message.startswith("GOAL_TOLERANCE_VIOLATED: j1 (module 1) ")
    assert "s after the trajectory's end (goal tolerance 0.5°)" in result.message
    error = float(result.message.split(") ")[1].split("°")[0])
    assert 0.5 < error < 1.5
    # the step ended goal_time_s after the trajectory's end, not the arm's settle time
    assert result.steps[3].finished == pytest.approx(0.0198 + 3.0 + 0.2, abs=0.05)


def test_without_tolerances_the_step_runs_as_before(tmp_path, project):
    trajectory_sequence(project)
    sim = run_on_sim("traj", tmp_path, root=project)
    assert sim.outcome.result.exit_code == 0, sim.outcome.result.message


@pytest.mark.parametrize("keys, message, column", [
    (", path_tolerance_deg: {j4: 5.0}", "path_tolerance_deg: j4 5° is looser than the arm "
     "file's control.max_following_error_deg 4°", None),
    (", goal_tolerance_deg: {j9: 0.1}", "goal_tolerance_deg: unknown joint 'j9'", None),
    (", goal_tolerance_deg: {j3: 0.1}", "goal_tolerance_deg: j3 is locked", None),
    (", path_tolerance_deg: {j4: true}", "", None),
    (", path_tolerance_deg: {j4: '1'}", "", None),
    (", goal_time_s: 0", "", None),
])
def test_bad_tolerances_are_refused_at_file_line_col(tmp_path, keys, message, column):
    from seqrun.service.checking import check_sequence

    (tmp_path / "rise.csv").write_text(RISE, encoding="utf-8")
    sequence = tmp_path / "t.yaml"
    sequence.write_text("name: t\nsteps:\n  - move_trajectory: {file: rise.csv%s}\n" % keys,
                        encoding="utf-8")
    start = {"j1": 0.0, "j2": -90.0, "j3": 0.0, "j4": -120.32, "j5": 0.0, "j6": 115.74,
             "j7": 0.0}
    check = check_sequence(sequence, start_deg=start, started=True, arm_file=ARM,
                           dry_run=False)
    assert check.errors
    first = str(check.errors[0])
    assert first.startswith(f"{sequence}:3:"), first
    assert message in first


# ---------------------------------------------------------------------- the service layer
def test_the_service_layer_runs_a_trajectory_with_its_tolerances_as_the_steps(session):
    """seqrun ros's path: the tolerances become the move_trajectory step's keys."""
    from seqrun.errors import Refused
    from seqrun.service.trajectories import JointTrajectory, TrajectoryPoint, run_trajectory

    start = session.telemetry.joints_deg()["j1"]
    points = tuple(TrajectoryPoint((math.radians(start + i),), 0.1 * i) for i in range(1, 21))
    trajectory = JointTrajectory(("j1",), points)
    with pytest.raises(Refused, match=r"^trajectory: path_tolerance_deg: j1 5° is looser "
                                      r"than the arm file's"):
        run_trajectory(session, trajectory, by="test",
                       tolerances=TrajectoryTolerances({"j1": 5.0}))
    result = run_trajectory(session, trajectory, by="test", tolerances=TrajectoryTolerances(
        {"j1": 1.0}, {"j1": 0.05}, 0.5)).wait(timeout=120)
    assert result.ok, result.message
    (copied,) = (result.run_dir / "inputs").rglob("ros_trajectory_*.yaml")
    text = copied.read_text(encoding="utf-8")
    assert ('path_tolerance_deg: {"j1": 1.0}, goal_tolerance_deg: {"j1": 0.05}, '
            'goal_time_s: 0.5}') in text


# ---------------------------------------------------------------------- the pure rules
def test_jtc_parameters_are_radians_and_0_means_not_set():
    names = ["j1", "j2", "j4"]
    tolerances = from_parameters({"constraints.j2.trajectory": math.radians(1.5),
                                  "constraints.j4.goal": math.radians(0.2),
                                  "constraints.j1.goal": 0.0,
                                  "constraints.goal_time": 0.5,
                                  "constraints.stopped_velocity_tolerance": 0.0,
                                  "rate": 100.0}, names)
    assert tolerances.path_deg == pytest.approx({"j2": 1.5})
    assert tolerances.goal_deg == pytest.approx({"j4": 0.2})
    assert tolerances.goal_time_s == 0.5
    assert from_parameters({}, names).empty


@pytest.mark.parametrize("values, reason", [
    ({"constraints.j2.trajectory": True}, "must be a number >= 0"),
    ({"constraints.j2.goal": -0.1}, "must be a number >= 0"),
    ({"constraints.j9.goal": 0.1}, "not one of constraints.goal_time"),
    ({"constraints.stopped_velocity_tolerance": 0.01}, "not supported"),
])
def test_bad_jtc_parameters_are_refused_in_one_line(values, reason):
    with pytest.raises(ValueError, match=reason):
        from_parameters(values, ["j1", "j2"])


def test_a_goals_fields_override_the_parameters_joint_by_joint():
    defaults = TrajectoryTolerances({"j1": 1.0, "j2": 2.0}, {"j1": 0.1}, 0.5)
    merged = override(defaults, TrajectoryTolerances({"j2": 3.0}, {}, None))
    assert merged == TrajectoryTolerances({"j1": 1.0, "j2": 3.0}, {"j1": 0.1}, 0.5)
    assert override(defaults, TrajectoryTolerances({}, {}, 2.0)).goal_time_s == 2.0


def test_a_tolerance_looser_than_the_arm_files_bound_is_refused_not_capped():
    arm = load_arm(ARM)
    bound = arm.control.max_following_error_deg
    assert problems(TrajectoryTolerances({"j2": bound}), arm) == []
    ((key, joint, line),) = problems(TrajectoryTolerances({}, {"j2": bound + 0.1}), arm)
    assert (key, joint) == ("goal_tolerance_deg", "j2") and "looser" in line


def test_the_constraint_parameters_are_documented():
    from seqrun.arm.trajectory_tolerances import PARAMETERS

    doc = (ROOT / "docs" / "ros2-node.md").read_text(encoding="utf-8")
    table = doc[doc.index("## Parameters"):]
    for name in PARAMETERS:
        assert f"| `{name}` |" in table, f"{name} not in the docs' table"


# ---------------------------------------------------------------------- seqrun ros
def ros_node(tmp_path, monkeypatch, *parameters: str):
    """A node (not spun) on a simulated arm, started with ``-p`` ``parameters``; returns
    (node, close)."""
    rclpy = pytest.importorskip("rclpy")
    from test_ros_node import domain_id

    from seqrun.clock import RealClock
    from seqrun.ros.node import SeqrunNode
    from seqrun.service import ArmSession
    from seqrun.service.connection import open_connection

    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.setattr("seqrun.ros.node.DISCOVERY_S", 0.2, raising=False)
    context = rclpy.Context()
    args = ["seqrun", "--ros-args", *[x for p in parameters for x in ("-p", p)]]
    rclpy.init(args=args, context=context, domain_id=domain_id())
    session = ArmSession(load_arm(ARM), open_connection(force_sim=True, clock=RealClock()),
                         log_root=tmp_path / "runs", poses_dir=ROOT / "poses")
    session.poll_status()
    assert session.arm_up().ok and session.home().ok

    def close(node=None) -> None:
        if node is not None:
            node.close()
        session.close()
        rclpy.shutdown(context=context)

    import uuid

    token = uuid.uuid4().hex[:8]
    try:
        node = SeqrunNode(session, arm_name=f"lwa3_{token}", context=context,
                          node_name=f"seqrun_{token}")
    except BaseException:
        close()
        raise
    return node, close


@pytest.mark.slow
def test_seqrun_ros_reads_jtcs_constraint_parameters(tmp_path, monkeypatch):
    node, close = ros_node(tmp_path, monkeypatch, "constraints.j2.trajectory:=0.02",
                           "constraints.j4.goal:=0.001", "constraints.goal_time:=0.5")
    try:
        assert node.tolerances.path_deg == pytest.approx({"j2": math.degrees(0.02)})
        assert node.tolerances.goal_deg == pytest.approx({"j4": math.degrees(0.001)})
        assert node.tolerances.goal_time_s == 0.5
        assert node.node.describe_parameter("constraints.j1.trajectory").read_only
        assert node.node.get_parameter("constraints.j1.goal").value == 0.0
        assert not node.node.has_parameter("constraints.j3.goal")  # locked

        # a goal's own tolerances override the parameters, joint by joint (JTC)
        class Codes:
            SUCCESSFUL, INVALID_GOAL, PATH_TOLERANCE_VIOLATED = 0, -1, -4
            GOAL_TOLERANCE_VIOLATED = -5

        class Goal:
            is_cancel_requested = False

            def __init__(self) -> None:
                self.ended: list[str] = []

            def abort(self) -> None:
                self.ended.append("aborted")

        from seqrun.service.trajectories import JointTrajectory, TrajectoryPoint

        one = JointTrajectory(("j1",), (TrajectoryPoint((0.1,), 1.0),))
        goal = Goal()
        code, text = node.follow_trajectory(one, goal, Codes,
                                            ([("j1", 0.01, 0.1, 0.0)], [], 0.0))
        assert (code, goal.ended) == (Codes.INVALID_GOAL, ["aborted"])
        assert text == ("trajectory: path_tolerance of j1: only position tolerances are "
                        "supported (velocity and acceleration must be 0)")
        goal = Goal()
        code, text = node.follow_trajectory(one, goal, Codes,
                                            ([("j2", 0.5, 0.0, 0.0)], [], 0.0))
        assert (code, goal.ended) == (Codes.INVALID_GOAL, ["aborted"])
        assert "path_tolerance_deg: j2 28.6479° is looser than the arm file's" in text
    finally:
        close(node)


@pytest.mark.slow
def test_seqrun_ros_refuses_a_constraint_looser_than_the_arm_files_bound(tmp_path,
                                                                          monkeypatch):
    from seqrun.errors import UserInputError

    with pytest.raises(UserInputError, match=r"^parameter constraints: path_tolerance_deg: "
                                             r"j2 57.2958° is looser"):
        ros_node(tmp_path, monkeypatch, "constraints.j2.trajectory:=1.0")
    with pytest.raises(UserInputError, match=r"must be a number >= 0, got 'x'"):
        ros_node(tmp_path, monkeypatch, "constraints.goal_time:=x")
