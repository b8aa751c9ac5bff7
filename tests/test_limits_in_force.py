"""Every move is planned within the limits in force: the arm file, the sequence's
set_limits, and the MaxVel/MaxAcc the modules still hold from before (issue 9, item 1)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from projecttree import make_project, shipped_arm
from runfolder import RunFolder
from seqrun.sequence.checks import static_check
from seqrun.clock import VirtualClock
from seqrun.service.connection import open_connection
from seqrun.service.dryrun import dry_run
from seqrun.results import EXIT_OK
from seqrun.arm.limits import ARM_FILE, READBACK, LimitsInForce
from seqrun.arm.planner import Limits
from seqrun.powercube.client import PowerCubeClient
from seqrun.powercube.protocol import ParamId
from seqrun.service.runner import run_sequence
from seqrun.sequence.loader import load_sequence
from seqrun.arm.poses import park_deg
from seqrun.drivers.powercube.units import to_module_rad
from simrun import run_on_sim

ARM = shipped_arm()

#: The repro of the issue: narrow three joints, then the shipped move to Totem.
NARROWED = """\
name: narrowed
description: set_limits narrows MaxVel, then a move
steps:
  - include: startup.yaml
  - set_limits: {max_velocity_deg_s: {j2: 5, j4: 5, j6: 5}}
  - move: {pose: totem}
"""


@pytest.fixture
def project(tmp_path: Path) -> Path:
    root = make_project(tmp_path / "project", sequences=("startup.yaml", "totem.yaml"))
    (root / "sequences" / "narrowed.yaml").write_text(NARROWED)
    return root


def test_the_repro_passes_validation_and_its_dry_run(project):
    check = static_check(project / "sequences" / "narrowed.yaml")
    assert check.valid, check.errors
    run = dry_run(check.loaded, check.arm, check.start_deg)
    assert run.passed, run.result.message
    move = run.result.steps[-1]
    assert move.detail["limits_in_force"]["j4"]["max_velocity_deg_s"] == 5
    assert move.detail["limits_in_force"]["j4"]["velocity_from"].startswith(
        "set_limits at ")
    assert move.detail["limits_in_force"]["j4"]["velocity_from"].endswith("narrowed.yaml:5:5")
    # Within the narrowed limit (a difference quotient of measured positions: 1 % slack).
    peaks = dict(zip(ARM.joint_names, move.detail["peak_measured_velocity_deg_s"]))
    assert all(peaks[n] <= 5.05 for n in ("j2", "j4", "j6"))


def test_the_repro_runs_and_the_report_says_which_limit_applied(project, tmp_path):
    outcome = run_on_sim("narrowed", tmp_path, root=project).outcome
    assert outcome.result.exit_code == EXIT_OK, outcome.result.message
    report = RunFolder(tmp_path / "run").report()
    move = report["steps"][-1]
    assert move["limits_in_force"]["j2"] == {
        "max_velocity_deg_s": 5.0, "velocity_from": move["limits_in_force"]["j2"]["velocity_from"],
        "max_acceleration_deg_s2": 60.0, "acceleration_from": ARM_FILE}
    assert "narrowed.yaml:5:5" in move["limits_in_force"]["j2"]["velocity_from"]
    assert set(move["limits_in_force"]) == {"j2", "j4", "j6"}


def _narrow_stored_max_vel(connection) -> None:
    """What an earlier run's set_limits left in the modules: MaxVel 5 deg/s on j4."""
    client = PowerCubeClient(connection.bus, connection.clock)
    try:
        client.set_param(ARM.joint("j4").module, ParamId.MAX_VEL, math.radians(5.0))
    finally:
        client.close()


def test_a_max_vel_stored_before_the_run_bounds_the_shipped_totem(project, tmp_path):
    outcome = run_on_sim("totem", tmp_path, root=project, before=_narrow_stored_max_vel).outcome
    assert outcome.result.exit_code == EXIT_OK, outcome.result.message
    report = RunFolder(tmp_path / "run").report()
    move = next(s for s in report["steps"] if s["kind"] == "move")
    assert move["limits_in_force"]["j4"]["velocity_from"] == READBACK
    assert move["limits_in_force"]["j4"]["max_velocity_deg_s"] == pytest.approx(5.0, abs=1e-4)
    [preflight] = RunFolder(tmp_path / "run").events("preflight")
    assert preflight["module_limits"]["j4"][0] == pytest.approx(5.0, abs=1e-3)
    assert any("holds MaxVel 5 deg/s" in note for note in preflight["notes"])


def test_set_limits_persists_in_the_simulated_modules_for_the_next_run(project, tmp_path):
    """The 'next day' of the issue: one simulated arm, two runs; the second (the shipped
    totem.yaml, which writes no MaxVel) plans within what the first left stored."""
    first = load_sequence(project / "sequences" / "narrowed.yaml")
    second = load_sequence(project / "sequences" / "totem.yaml")
    connection = open_connection(force_sim=True, clock=VirtualClock())
    try:
        one = run_sequence(first, ARM, connection, log_dir=None, confirm=lambda p: True)
        assert one.result.exit_code == EXIT_OK, one.result.message
        # back down to Park for the second run to have something to do
        sim = connection.bus.arm
        sim.set_positions({j.module: to_module_rad(j, v)
                           for j, v in zip(ARM.joints, park_deg(project / "poses").values())})
        two = run_sequence(second, ARM, connection, log_dir=None, confirm=lambda p: True)
    finally:
        connection.close()
    assert two.result.exit_code == EXIT_OK, two.result.message
    move = next(s for s in two.result.steps if s.kind == "move")
    assert move.detail["limits_in_force"]["j4"]["velocity_from"] == READBACK


def test_limits_in_force_take_the_narrowest_and_name_it():
    limits = LimitsInForce(ARM)
    assert limits.velocity("j2").source == ARM_FILE and limits.narrowed() == {}
    limits.read_back({"j2": (114.6, 114.6), "j4": (5.0, 114.6)})
    assert limits.velocity("j2").source == ARM_FILE  # wider than the arm file: arm file
    assert limits.velocity("j4") == limits.velocity("j4").__class__(5.0, READBACK)
    limits.written("set_limits at s.yaml:5:5", {"j4": 20.0}, {"j4": 30.0})
    assert limits.velocity("j4").value == 20.0
    assert limits.velocity("j4").source == "set_limits at s.yaml:5:5"
    # the module must out-accelerate the plan by module_acceleration_factor
    factor = ARM.control.module_acceleration_factor
    assert limits.acceleration("j4").value == pytest.approx(30.0 / factor)
    velocity, acceleration = limits.maxima()
    plan = Limits.from_arm(ARM, max_velocity_deg_s=velocity, max_acceleration_deg_s2=acceleration)
    keep = 1 - ARM.control.tracking_reserve
    assert np.degrees(plan.velocity[ARM.index("j4")]) == pytest.approx(20.0 * keep)
    assert np.degrees(plan.acceleration[ARM.index("j4")]) == pytest.approx(30.0 / factor)


def test_sim_serve_keeps_a_written_max_vel_for_the_next_client():
    """`seqrun sim serve` is one simulated arm for all its clients: what one run wrote
    (set_limits' MaxVel) is what the next run's preflight reads back."""
    import can

    from seqrun.clock import RealClock
    from seqrun.sim.arm import SimArm
    from seqrun.sim.network import SimNetwork
    from seqrun.sim.socketcand import SocketcandServer

    clock = RealClock()
    network = SimNetwork(clock, SimArm(clock), spin_window=0.0)

    def client_of(server):
        bus = can.Bus(interface="socketcand", host="127.0.0.1", port=server.port,
                      channel="can0", ignore_config=True)
        return bus, PowerCubeClient(bus, clock, response_timeout=0.5)

    with SocketcandServer(network, port=0, channel="can0") as server:
        server.start()
        bus, client = client_of(server)
        try:
            client.set_param(4, ParamId.MAX_VEL, math.radians(5.0))
        finally:
            client.close()
            bus.shutdown()
        bus, client = client_of(server)
        try:
            stored = client.get_param(4, ParamId.MAX_VEL)
        finally:
            client.close()
            bus.shutdown()
    assert math.degrees(float(stored)) == pytest.approx(5.0, abs=1e-4)
