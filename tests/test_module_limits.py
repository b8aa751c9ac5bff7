"""The limits in the modules: `seqrun limits show|set`, MaxCur in set_limits and the arm
file, and the simulator's current limit (a joint that needs more than MaxCur lags and the
run halts on its following error; or, with ``current_limit_halts``, the module stops)."""

from __future__ import annotations

import json
import shutil

import pytest
from typer.testing import CliRunner

from projecttree import ROOT, shipped_arm
from seqrun.cli import app
from seqrun.clock import RealClock, VirtualClock
from seqrun.powercube.codec import SetMotion, SetParam
from seqrun.powercube.protocol import MotionMode, ParamId, StateFlag
from seqrun.sim.arm import SimArm
from seqrun.sim.module import ModuleOptions, SimModule
from seqrun.sim.network import SimNetwork
from seqrun.sim.socketcand import SocketcandServer
from simrun import run_on_sim

ARM = shipped_arm()
F = StateFlag


@pytest.fixture(autouse=True)
def state_dir(tmp_path, monkeypatch):
    """This machine's zero records: the test's own."""
    monkeypatch.setenv("SEQRUN_STATE_DIR", str(tmp_path / "state"))


def serve(faults=(), pose: str = "park"):
    """A served arm powered on at ``pose``, its zero recorded there (``limits set`` converts
    positions with the zero in force, confirmed after a power-on: issue 43)."""
    from seqrun.drivers.base import ArmIdentity
    from seqrun.service.zero import ZeroStore

    clock = RealClock()
    arm = SimArm(clock, faults=list(faults), power_on_pose=pose)
    ZeroStore(ArmIdentity.of(arm.serials)).set_record(
        pose, by="test", joints_deg=ARM.power_off_joints_deg(pose))
    server = SocketcandServer(SimNetwork(clock, arm, spin_window=0.0), port=0)
    server.start()
    return server


def bus(server) -> list[str]:
    return ["-i", "socketcand", "--bus-kwargs", "host=127.0.0.1", f"port={server.port}"]


#: What ``limits set`` adds: the operator's word that the arm stands in Park.
CONFIRMED = ["--zero-confirmed", "park"]


def limits(server, *words) -> dict:
    confirmed = CONFIRMED if words[:1] == ("set",) else []
    result = CliRunner().invoke(app, ["limits", *words, "--json", *confirmed, *bus(server)])
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)


# -- seqrun limits show / set ----------------------------------------------------------------

def test_show_marks_every_difference_and_set_writes_the_arm_files_values():
    server = serve()
    try:
        before = limits(server, "show")
        j1 = before["joints"][0]["limits"]
        # A freshly powered-on module holds narrower position limits and a higher MaxCur.
        assert j1["min_deg"] == {"module": -120.0003, "arm_file": -180.0, "differs": True}
        assert j1["max_current_a"] == {"module": 12.0, "arm_file": 2.0, "differs": True}
        assert before["differences"] == 35    # 5 values x 7 joints
        written = limits(server, "set")
        assert written["written"] == 35 and written["differences"] == 0
        after = limits(server, "show")       # read again by another process: stored
        assert after["differences"] == 0
        assert after["joints"][3]["limits"]["max_deg"]["module"] == 120.0   # via the offset
        assert all(j["limits"]["max_current_a"]["module"] == 2.0 for j in after["joints"])
        text = CliRunner().invoke(app, ["limits", "show", *bus(server)]).output
        assert "every value as the arm file says" in text
    finally:
        server.shutdown()


def test_show_reads_with_the_zero_in_force_not_the_arm_files_default():
    """Powered off in Totem (zero record: totem): `limits set` writes the limits with the
    Totem offsets; `limits show` read them with Park's and reported j2, j4 and j6 wrong."""
    server = serve(pose="totem")
    try:
        result = CliRunner().invoke(app, ["limits", "set", "--json", "--zero-confirmed",
                                          "totem", *bus(server)])
        assert result.exit_code == 0, result.output
        after = limits(server, "show")
        assert after["differences"] == 0, after
        assert "totem" in after["zero"].lower()
        assert after["joints"][3]["limits"]["max_deg"]["module"] == 120.0
        text = CliRunner().invoke(app, ["limits", "show", *bus(server)]).output
        assert "zero: " in text and "totem" in text.lower()
    finally:
        server.shutdown()


def test_show_as_text_marks_the_differences():
    result = CliRunner().invoke(app, ["limits", "show", "--sim"])
    assert result.exit_code == 0, result.output
    assert "-120.000 ≠ -180.000" in result.output
    assert "35 value(s) differ from the arm file" in result.output


def test_set_of_some_joints_writes_only_theirs():
    server = serve()
    try:
        written = limits(server, "set", "--joints", "j2")
        assert written["written"] == 5
        assert [j["joint"] for j in written["joints"]
                if not any(v["differs"] for v in j["limits"].values())] == ["j2"]
    finally:
        server.shutdown()


def test_set_exits_3_when_a_module_does_not_answer():
    server = serve(["5:no_ack@0"])
    try:
        result = CliRunner().invoke(app, ["limits", "set", "--response-timeout-ms", "20",
                                          *CONFIRMED, *bus(server)])
    finally:
        server.shutdown()
    assert result.exit_code == 3, result.output
    # (the zero's identity is read first since issue 43: that read names the silent module)
    last = result.output.strip().splitlines()[-1]
    assert last.startswith("error: cannot read the modules' state: module 5: no "
                           "acknowledge"), result.output


# -- set_limits: max_current_a -------------------------------------------------------------

def _campaign(tmp_path, steps: str, arm_edit=None) -> str:
    root = tmp_path / "campaign"
    shutil.copytree(ROOT / "sequences", root / "sequences")
    shutil.copytree(ROOT / "arms", root / "arms")
    shutil.copytree(ROOT / "poses", root / "poses")
    if arm_edit is not None:
        path = root / "arms" / "lwa3.yaml"
        path.write_text(arm_edit(path.read_text()))
    (root / "sequences" / "current.yaml").write_text(
        "name: current\ndescription: MaxCur\nsteps:\n  - include: startup.yaml\n" + steps)
    return root


def _validate(root) -> tuple[int, str]:
    result = CliRunner().invoke(app, ["validate", str(root / "sequences" / "current.yaml")])
    return result.exit_code, result.output


def test_validation_refuses_a_current_above_the_arm_files(tmp_path):
    root = _campaign(tmp_path, "  - set_limits: {max_current_a: {j1: 2.5}}\n")
    code, output = _validate(root)
    assert code == 1
    assert "max_current_a of j1 2.5 A is above the arm's maximum 2 A" in output


def test_validation_refuses_a_current_the_arm_file_does_not_bound(tmp_path):
    root = _campaign(tmp_path, "  - set_limits: {max_current_a: {j1: 1.0}}\n",
                     arm_edit=lambda text: text.replace("max_current_a: 2.0}", "}", 1))
    code, output = _validate(root)
    assert code == 1
    assert "the arm file gives no max_current_a for j1" in output


def test_set_limits_writes_maxcur_read_back(tmp_path):
    root = _campaign(tmp_path, "  - set_limits: {max_current_a: {j2: 1.5}}\n")
    run = run_on_sim("current", tmp_path, root=root)
    assert run.outcome.result.exit_code == 0
    currents = {m: run.sim.module(m).parameter(ParamId.MAX_CUR) for m in range(1, 8)}
    assert currents == {1: 2.0, 2: 1.5, 3: 2.0, 4: 2.0, 5: 2.0, 6: 2.0, 7: 2.0}


# -- the simulator's current limit ---------------------------------------------------------

def _module(options=None) -> tuple[VirtualClock, SimModule]:
    clock = VirtualClock()
    module = SimModule(1, clock, options=options or ModuleOptions(home_ok_at_power_on=True))
    return clock, module


def test_within_maxcur_the_ramp_is_the_planned_one_and_cur_reads_its_current():
    clock, module = _module()
    module.handle(SetParam(1, ParamId.MAX_CUR, 2.0))
    module.handle(SetMotion(1, MotionMode.FRAMP, 1.0))
    clock.advance(0.1)
    assert not module.state() & F.CURLIMIT
    assert 0 < module.parameter(ParamId.CUR) <= 2.0
    clock.advance(5.0)
    assert module.position() == pytest.approx(1.0)


def test_above_maxcur_the_joint_lags_with_curlimit():
    clock, fast = _module()
    clock2, slow = _module()
    slow.handle(SetParam(1, ParamId.MAX_CUR, 0.5))
    for clk, module in ((clock, fast), (clock2, slow)):
        module.handle(SetMotion(1, MotionMode.FRAMP, 1.0))
        clk.advance(0.5)
    assert slow.state() & F.CURLIMIT and not slow.state() & F.FAULTS
    assert slow.position() < 0.5 * fast.position()
    assert abs(slow.parameter(ParamId.CUR)) <= 0.5 + 1e-6


def test_current_limit_halts_switch_stops_the_module():
    clock, module = _module(ModuleOptions(home_ok_at_power_on=True, current_limit_halts=True))
    module.handle(SetParam(1, ParamId.MAX_CUR, 0.5))
    module.handle(SetMotion(1, MotionMode.FRAMP, 1.0))
    clock.advance(0.5)
    assert module.state() & F.CURLIMIT and module.state() & F.ERROR
    assert module.position() == 0.0


MOVE_J1 = ("  - set_limits: {max_current_a: {j1: 0.3}}\n"
           "  - move: {joints: {j1: 60}, velocity_scale: 1.0}\n")


def test_a_joint_short_of_current_ends_the_run_in_a_following_error(tmp_path):
    root = _campaign(tmp_path, MOVE_J1)
    run = run_on_sim("current", tmp_path, root=root)
    assert run.outcome.result.exit_code == 3
    assert run.outcome.result.fault["cause"] == "following_error", run.outcome.result.message
    assert all(s & F.HALTED for s in run.sim.states().values())


def test_with_current_limit_halts_the_module_fault_ends_the_run(tmp_path, monkeypatch):
    monkeypatch.setenv("SEQRUN_SIM_OPTIONS", "current_limit_halts")
    root = _campaign(tmp_path, MOVE_J1)
    run = run_on_sim("current", tmp_path, root=root)
    assert run.outcome.result.exit_code == 3
    assert run.outcome.result.fault["cause"] != "following_error", run.outcome.result.message
    assert run.sim.states()[1] & F.CURLIMIT
    assert all(s & F.HALTED for s in run.sim.states().values())
