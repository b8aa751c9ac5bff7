"""Home: the simulator's homing (no travel on a PRL; travel to the home switch as an
option), the driver's confirmed Home, and ``seqrun home [--joints …]``."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from projecttree import shipped_arm
from seqrun.cli import app
from seqrun.clock import RealClock, VirtualClock
from seqrun.drivers.powercube import PowerCubeDriver
from seqrun.powercube.client import PowerCubeClient
from seqrun.powercube.codec import CommandRequest, SetMotion
from seqrun.powercube.protocol import CommandId, MotionMode, ShortState, StateFlag
from seqrun.sim.arm import SimArm
from seqrun.sim.bus import SimBus
from seqrun.sim.module import ModuleOptions, SimModule
from seqrun.sim.network import SimNetwork
from seqrun.sim.socketcand import SocketcandServer

ARM = shipped_arm()
F = StateFlag
TRAVEL = ModuleOptions(homing_travel=True, home_switch_position=0.3)


# -- the simulator ------------------------------------------------------------------------

def test_a_prl_homes_at_once_without_travel():
    clock = VirtualClock()
    module = SimModule(2, clock, position=0.5)
    module.handle(CommandRequest(2, CommandId.HOME))
    assert module.state() & F.HOME_OK and not module.state() & F.MOTION
    assert module.position() == 0.5


def test_homing_travel_runs_to_the_switch_with_motion_and_no_home_ok_on_the_way():
    clock = VirtualClock()
    module = SimModule(2, clock, position=-0.2, options=TRAVEL)
    module.handle(CommandRequest(2, CommandId.HOME))
    clock.advance(1.0)
    state = module.state()
    assert state & F.MOTION and not state & F.HOME_OK and not state & F.BRAKEACTIVE
    assert -0.2 < module.position() < 0.3
    assert module.velocity() == pytest.approx(0.1)     # at FHomeVel (0.1 rad/s)
    # Motion commands are refused on the way (not homed): the extended ack says NOT_OK.
    ack = module.handle(SetMotion(2, MotionMode.FRAMP_ACK, 1.0))
    assert ack.state & ShortState.NOT_OK
    clock.advance(10.0)   # 0.5 rad at 0.1 rad/s: about 5.2 s in all
    state = module.state()
    assert state & F.HOME_OK and state & F.SWR and not state & F.MOTION
    assert module.position() == pytest.approx(0.3)


def test_a_halt_while_homing_leaves_the_module_not_homed():
    clock = VirtualClock()
    module = SimModule(2, clock, position=-0.2, options=TRAVEL)
    module.handle(CommandRequest(2, CommandId.HOME))
    clock.advance(1.0)
    module.handle(CommandRequest(2, CommandId.HALT))
    module.handle(CommandRequest(2, CommandId.RESET))
    clock.advance(10.0)
    assert not module.state() & F.HOME_OK and not module.state() & F.MOTION
    assert module.position() < 0.3


# -- the driver -----------------------------------------------------------------------------

@pytest.fixture
def driver(request):
    options, positions = getattr(request, "param", (None, None))
    clock = VirtualClock()
    bus = SimBus(f"home-{request.node.name}", clock=clock, options=options,
                 positions=positions, ignore_config=True)
    client = PowerCubeClient(bus, clock, response_timeout=0.05)
    yield PowerCubeDriver(client, ARM), bus.arm
    client.close()
    bus.shutdown()


def test_home_is_confirmed_by_every_module(driver):
    drv, arm = driver
    assert not any(s & F.HOME_OK for s in arm.states().values())
    result = drv.confirm("home")
    assert result.confirmed and result.sent, result.describe_unconfirmed()
    assert sorted(result.states) == list(range(1, 8))
    assert all(s & F.HOME_OK for s in arm.states().values())


@pytest.mark.parametrize("driver", [(TRAVEL, [-0.2, 0.0, 0.3, 0.8, 0.3, 0.3, 0.3])],
                         indirect=True)
def test_home_waits_for_the_travel_to_the_switch(driver):
    drv, arm = driver
    result = drv.confirm("home")
    assert result.confirmed, result.describe_unconfirmed()
    assert result.duration_s > 5.0    # module 4's 0.5 rad at 0.1 rad/s
    assert all(s & F.HOME_OK and not s & F.MOTION for s in arm.states().values())
    assert arm.module(4).position() == pytest.approx(0.3)


def test_home_of_some_joints_homes_only_their_modules(driver):
    drv, arm = driver
    result = drv.confirm("home", [2, 3])
    assert result.confirmed and sorted(result.states) == [2, 3]
    homed = {m for m, s in arm.states().items() if s & F.HOME_OK}
    assert homed == {2, 3}


def test_home_is_not_sent_to_a_halted_arm(driver):
    drv, arm = driver
    drv.halt(None)
    result = drv.confirm("home")
    assert not result.sent and not result.confirmed
    assert "reset them first" in result.error
    assert not any(s & F.HOME_OK for s in arm.states().values())


# -- the command ----------------------------------------------------------------------------

def test_seqrun_home_confirms_and_says_so():
    result = CliRunner().invoke(app, ["home", "--sim"])
    assert result.exit_code == 0, result.output
    assert "Home confirmed by modules 1, 2, 3, 4, 5, 6, 7" in result.output


def test_seqrun_home_of_an_unknown_joint_is_one_line():
    result = CliRunner().invoke(app, ["home", "--sim", "--joints", "j2,j9"])
    assert result.exit_code == 2
    assert result.output.strip().splitlines() == [
        "error: unknown joint(s) j9: arm 'Schunk LWA 3 (RV&D facility)' has j1, j2, j3, j4, "
        "j5, j6, j7"]


def test_seqrun_home_of_a_halted_arm_exits_3_saying_reset_first(tmp_path, monkeypatch):
    from seqrun.drivers.base import ArmIdentity
    from seqrun.service.zero import ZeroStore

    monkeypatch.setenv("SEQRUN_STATE_DIR", str(tmp_path / "state"))
    clock = RealClock()
    arm = SimArm(clock, faults=["3:halt@0"])
    ZeroStore(ArmIdentity.of(arm.serials)).set_record(
        "park", by="test", joints_deg=ARM.power_off_joints_deg("park"))
    server = SocketcandServer(SimNetwork(clock, arm, spin_window=0.0), port=0)
    server.start()
    try:
        result = CliRunner().invoke(app, ["home", "--joints", "j1,j3", "--zero-confirmed",
                                          "park", "-i", "socketcand",
                                          "--bus-kwargs", "host=127.0.0.1",
                                          f"port={server.port}"])
    finally:
        server.shutdown()
    assert result.exit_code == 3, result.output
    last = result.output.strip().splitlines()[-1]
    assert last.startswith("error: home not sent: module(s) 3 halted or in error: reset "
                           "them first"), result.output


# -- the console's Home (the session) -------------------------------------------------------

def test_the_sessions_home_waits_for_a_module_travelling_to_its_switch(tmp_path, monkeypatch):
    from seqrun.arm.description import load_arm
    from seqrun.service.connection import open_connection
    from seqrun.service.session import ArmSession
    from projecttree import ROOT

    monkeypatch.setenv("SEQRUN_SIM_OPTIONS", "homing_travel home_switch_position=0.6")
    connection = open_connection(force_sim=True, clock=VirtualClock())
    session = ArmSession(load_arm(ROOT / "arms" / "lwa3.yaml"), connection, status_hz=0,
                         log_root=tmp_path / "runs", poses_dir=ROOT / "poses")
    try:
        result = session.home()      # 0.6 rad at 0.1 rad/s: over 6 s
        assert result.ok, result
        arm = connection.bus.arm
        assert all(s & F.HOME_OK and s & F.SWR for s in arm.states().values())
        assert arm.module(2).position() == pytest.approx(0.6)
    finally:
        session.close()
