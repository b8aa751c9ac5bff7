"""The driver seam (issues 10.3, 25.1): the executor speaks user joints, never PowerCube.

- ``seqrun/executor.py`` imports nothing from ``seqrun.powercube`` (nor the PowerCube
  driver family), and the step modules neither build codec requests nor import the
  executor (the import cycle executor -> steps -> confirm -> executor is gone);
- a driver family that is not PowerCube at all (an ideal arm, in this file), registered in
  ``seqrun.drivers.registry.DRIVERS`` with one line and named by its arm file, runs a whole
  shipped sequence the way ``seqrun run`` assembles one (``open_driver``, the runner, the
  executor): reset, home, set_limits, moves, waits, a checkpoint;
- a fault that driver reports mid-move ends like any fault: Halt through the driver,
  confirmed, exit 3 with the cause the driver decoded.
"""

from __future__ import annotations

import ast
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from projecttree import ROOT, shipped_arm
from seqrun.arm.planner import Limits, MovePlan
from seqrun.arm.poses import pose_joints_deg
from seqrun.clock import VirtualClock
from seqrun.drivers import registry
from seqrun.arm.joint_values import JointLimits, JointState, LimitValues
from seqrun.drivers.base import (ArmDriver, ArmIdentity, ArmPoll, CommandConfirmation,
                                 JointReading, MotionRefused)
from seqrun.errors import UserInputError
from seqrun.executor import Executor
from seqrun.sequence.checks import check_from_arm
from seqrun.results import EXIT_FAULT, EXIT_OK
from seqrun.sequence.loader import load_sequence
from seqrun.service.runner import run_sequence

ARM = shipped_arm()
#: Modules that only PowerCube code may import.
POWERCUBE_ONLY = ("seqrun.powercube", "seqrun.drivers.powercube")


def imported_modules(path: Path) -> set[str]:
    """Every module ``path`` imports, at any level (function bodies included)."""
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return names


def powercube_imports(path: Path) -> list[str]:
    return sorted(name for name in imported_modules(path)
                  if any(name == p or name.startswith(p + ".") for p in POWERCUBE_ONLY))


def test_the_executor_imports_nothing_from_powercube():
    assert powercube_imports(ROOT / "seqrun" / "executor.py") == []
    for path in sorted((ROOT / "seqrun" / "execution").glob("*.py")):
        assert powercube_imports(path) == [], path.name
    import seqrun.executor as executor

    leaked = {name: value.__module__ for name, value in vars(executor).items()
              if getattr(value, "__module__", "").startswith(POWERCUBE_ONLY)}
    assert leaked == {}


def test_steps_build_no_requests_and_do_not_import_the_executor():
    for path in sorted((ROOT / "seqrun" / "steps").glob("*.py")):
        assert powercube_imports(path) == [], path.name
        assert "seqrun.executor" not in imported_modules(path), path.name


# -- a driver that is not PowerCube ---------------------------------------------------------

@dataclass(frozen=True)
class IdealCycleState:
    """This driver's per-cycle state: bit 0 refuses motion, bit 1 moving."""

    code: int

    @property
    def refuses_motion(self) -> bool:
        return bool(self.code & 1)

    @property
    def moving(self) -> bool:
        return bool(self.code & 2)

    def describe(self) -> str:
        return "refuses" if self.refuses_motion else "ok"

    def __int__(self) -> int:
        return self.code


class IdealBus:
    """What the ideal arm's driver is opened on (a connection's ``clock``, ``bus``): the
    arm stands at ``start_deg``, powered on, and may overheat one joint at a plan time."""

    def __init__(self, start_deg: Mapping[str, float], *,
                 overheat: tuple[int, float] | None = None) -> None:
        self.clock = VirtualClock()
        self.bus = (dict(start_deg), overheat)
        self.description, self.is_simulator, self.faults = "the ideal arm", True, []
        self.opened: list[IdealArm] = []


class IdealArm:
    """The driver of an arm whose joints are exactly where the plan says (user degrees);
    it starts powered on (not homed) and can be told to overheat one joint at a plan
    time. Registered as the driver "ideal" by the tests that use it."""

    FAULT_FLAGS = frozenset({"HOT", "HALTED"})
    HOMED_FLAG = "HOMED"

    def __init__(self, start_deg: Mapping[str, float], *,
                 overheat: tuple[int, float] | None = None) -> None:
        self.modules = list(ARM.module_ids)
        self.positions = np.array([start_deg[j.name] for j in ARM.joints], dtype=float)
        self.homed_ = dict.fromkeys(self.modules, False)
        self.halted = dict.fromkeys(self.modules, False)
        self.overheated: set[int] = set()
        self.overheat = overheat
        self.limits = [JointLimits(math.degrees(-3.0), math.degrees(3.0), math.degrees(1.0),
                                   math.degrees(1.0)) for _ in self.modules]
        self.calls: list[str] = []
        self.cycles = 0
        self.closed = False
        self.mark: int | None = None

    # -- the family (what the registry asks of the class)
    @classmethod
    def open(cls, arm, connection: IdealBus, *,
             response_timeout_s: float | None = None) -> IdealArm:
        start_deg, overheat = connection.bus
        driver = cls(start_deg, overheat=overheat)
        connection.opened.append(driver)
        return driver

    @staticmethod
    def cycle_state(code: int) -> IdealCycleState:
        return IdealCycleState(code)

    @classmethod
    def simulator_positions(cls, arm, joints_deg: Mapping[str, float]) -> dict[int, float]:
        return {j.module: joints_deg[j.name] for j in arm.joints}

    # -- state
    def _state(self, module: int) -> JointState:
        hot, halted, homed = module in self.overheated, self.halted[module], self.homed_[module]
        faulted = hot or halted
        return JointState(homed=homed, halted=halted, moving=False, faulted=faulted,
                          cause="overheated" if hot else "halted" if halted else "not_homed",
                          text=("HOT " if hot else "") + ("HALTED " if halted else "")
                          + ("HOMED" if homed else "NOT_HOMED"),
                          fault_text="HOT" if hot else "HALTED" if halted else "",
                          cycle_code=int(faulted or not homed))

    def _reading(self) -> JointReading:
        return JointReading(self.positions.copy(),
                            {m: IdealCycleState(self._state(m).cycle_code)
                             for m in self.modules})

    # -- the ArmDriver calls
    def use_arm(self, arm) -> None:
        self.calls.append("use_arm")

    def configure(self, *, cycle_s: float, run_limits: Limits, command_mode: str,
                  emit: Callable[..., None]) -> None:
        self.calls.append("configure")

    def read(self) -> JointReading:
        return self._reading()

    def read_states(self, modules: Sequence[int] | None = None) -> dict[int, JointState]:
        return {m: self._state(m) for m in (self.modules if modules is None else modules)}

    def read_state(self, module: int) -> JointState:
        return self._state(module)

    def start_motion(self, moving: list[int], limits: Limits, *,
                     command_mode: str | None = None) -> None:
        self.calls.append("start_motion")

    def cycle(self, plan: MovePlan, t: float, moving: list[int],
              measured_deg: np.ndarray) -> JointReading:
        self.cycles += 1
        if self.overheat is not None and t >= self.overheat[1]:
            self.overheated.add(self.overheat[0])
        for i in moving:
            module = self.modules[i]
            if not self._state(module).ready:
                raise MotionRefused(module, IdealCycleState(1))
            self.positions[i] = math.degrees(plan.at(t)[0][i])
        return self._reading()

    def end_motion(self) -> None:
        self.calls.append("end_motion")

    def reset(self, modules: Sequence[int] | None) -> None:
        for m in self.modules if modules is None else modules:
            self.halted[m] = False
            self.overheated.discard(m)

    def home(self, modules: Sequence[int] | None) -> None:
        for m in self.modules if modules is None else modules:
            self.homed_[m] = True

    def halt(self, modules: Sequence[int] | None) -> None:
        for m in self.modules if modules is None else modules:
            self.halted[m] = True

    def halt_and_confirm(self) -> CommandConfirmation:
        self.calls.append("halt_and_confirm")
        self.halt(None)
        return CommandConfirmation("halt", tuple(self.modules), sent=True,
                                   states=self.read_states(), attempts=1)

    def halt_now(self, *, wait: bool = True) -> None:
        self.halt(None)

    def confirm(self, command: str, modules: Sequence[int] | None = None
                ) -> CommandConfirmation:
        getattr(self, command)(modules)
        return CommandConfirmation(command, tuple(self.modules), sent=True,
                                   states=self.read_states(), attempts=1)

    def session_mark(self) -> int | None:
        return self.mark

    def write_session_mark(self, mark: int) -> bool:
        self.mark = mark
        return True

    def poll(self, *, tolerate_loss: bool = False) -> ArmPoll:
        return ArmPoll(self.positions.tolist(), [0.0] * len(self.modules), self.read_states())

    def identity(self) -> ArmIdentity:
        return ArmIdentity.of({m: f"ideal-{m}" for m in self.modules})

    def homed(self) -> bool:
        return all(self.homed_.values())

    def watch_foreign(self, on_foreign: Callable[[Any], None]) -> None:
        self.calls.append("watch_foreign")  # the ideal arm has no other master

    def add_frame_listener(self, listener: Callable[[Any], None]) -> None: ...

    def remove_frame_listener(self, listener: Callable[[Any], None]) -> None: ...

    def describe_error(self, exc: BaseException) -> str:
        return str(exc)

    def read_limits(self) -> list[JointLimits]:
        return list(self.limits)

    def write_limits(self, values: Mapping[str, LimitValues]) -> int:
        for i, joint in enumerate(ARM.joints):
            if joint.name in values:
                v = values[joint.name]
                self.limits[i] = JointLimits(v.min_deg, v.max_deg,
                                             self.limits[i].max_velocity_deg_s,
                                             self.limits[i].max_acceleration_deg_s2)
        self.calls.append("write_limits")
        return 2 * len(values)

    def enable_watchdog(self, alive: Callable[[float], bool]) -> None:
        self.calls.append("enable_watchdog")

    def stop_watchdog_keeper(self) -> None:
        self.calls.append("stop_watchdog_keeper")

    def disable_watchdog(self) -> None:
        self.calls.append("disable_watchdog")

    def close(self) -> None:
        self.calls.append("close")
        self.closed = True


#: The arm file of an ideal arm: the shipped one, naming the ideal driver.
IDEAL = ARM.model_copy(update={"driver": "ideal"})


@pytest.fixture
def ideal_driver(monkeypatch):
    """The ideal arm's driver family, registered the way every family is: one line."""
    monkeypatch.setitem(registry.DRIVERS, "ideal", f"{__name__}:IdealArm")


def run_opsafe(bus: IdealBus):
    """opsafe.yaml assembled as ``seqrun run`` assembles a run: the registry opens the
    arm file's driver on the connection, the runner builds the executor around it."""
    loaded = load_sequence(ROOT / "sequences" / "opsafe.yaml")
    events: list[dict] = []
    outcome = run_sequence(loaded, IDEAL, bus, log_dir=None, confirm=lambda prompt: True,
                           listeners=[events.append])
    (driver,) = bus.opened
    return outcome.executor, outcome.result, events, driver


def park() -> dict[str, float]:
    return pose_joints_deg("park", ROOT / "poses")


def test_a_driver_that_is_not_powercube_runs_a_whole_sequence(ideal_driver):
    executor, result, events, driver = run_opsafe(IdealBus(park()))
    assert isinstance(driver, ArmDriver)
    assert result.exit_code == EXIT_OK, result.message
    assert executor.driver is driver and executor.client is None
    # Every step ran through the driver: homed, limits written, the moves streamed.
    assert all(driver.homed_.values()) and "write_limits" in driver.calls
    assert driver.calls.count("start_motion") == 2 and driver.cycles > 100
    assert "halt_and_confirm" not in driver.calls and "disable_watchdog" in driver.calls
    # The runner watched for another master and closed the driver it opened.
    assert "watch_foreign" in driver.calls and driver.closed
    opsafe = pose_joints_deg("opsafe", ROOT / "poses")
    assert np.allclose(driver.positions, [opsafe[j.name] for j in ARM.joints], atol=1e-6)
    assert [s.status for s in result.steps] == ["passed"] * len(result.steps)
    assert any(e["type"] == "setpoint" for e in events)


def test_a_fault_the_driver_reports_mid_move_halts_through_it(ideal_driver):
    # module 3 overheats 1 s into a move
    _, result, events, driver = run_opsafe(IdealBus(park(), overheat=(3, 1.0)))
    assert result.exit_code == EXIT_FAULT
    assert driver.calls.count("halt_and_confirm") == 1
    assert result.fault["cause"] == "overheated" and result.fault["module"] == 3
    assert result.fault["halt_confirmed"] is True
    assert "module 3 (j3): HOT" in result.message
    assert [e["type"] for e in events].count("halt_confirmed") == 1


def test_the_powercube_driver_is_an_arm_driver():
    from seqrun.drivers import as_driver
    from seqrun.drivers.powercube import PowerCubeDriver
    from seqrun.powercube.client import PowerCubeClient
    from seqrun.sim.bus import SimBus

    clock = VirtualClock()
    with SimBus("driver-seam", clock=clock) as bus:
        client = PowerCubeClient(bus, clock)
        driver = as_driver(client, ARM)
        assert isinstance(driver, PowerCubeDriver) and isinstance(driver, ArmDriver)
        assert as_driver(driver, ARM) is driver
        reading = driver.read()
        # Powered on at Park: the driver reports Park in user degrees (offsets applied).
        assert reading.positions_deg == pytest.approx([park()[j.name] for j in ARM.joints])
        # Freshly powered on: every joint refuses motion, its full state says not homed.
        assert all(state.refuses_motion for state in reading.states.values())
        states = driver.read_states()
        assert all(not s.homed and not s.faulted and s.cause == "not_homed"
                   for s in states.values())
        client.close()


def test_measurements_carry_the_flags_and_faults_the_driver_decoded():
    """A face's flags come from the driver's own states, never from PowerCube codes: the
    ideal arm's overheated joint is a fault with its own names (decoded as PowerCube, its
    cycle code 1 read "NOT_OK" and its full state "HOT HALTED HOMED" no fault at all)."""
    driver = IdealArm(park(), overheat=(3, 1.0))
    loaded = load_sequence(ROOT / "sequences" / "opsafe.yaml")
    executor = Executor(driver, IDEAL, VirtualClock(), sequence_check=check_from_arm,
                        poses_dir=loaded.poses_dir,
                        confirm=lambda prompt: True)
    subscription = executor.events.subscribe(maxsize=100_000, name="test")
    result = executor.run(loaded)
    assert result.exit_code == EXIT_FAULT
    measurements = [e for e in subscription.drain() if e.type == "measurement"]
    first, after_halt = measurements[0], measurements[-1]
    # Not homed yet: no fault in the full state the preflight read, the driver's name for it.
    assert first.source == "preflight" and not first.fault
    assert first.flags["j1"] == ("NOT_HOMED",)
    assert after_halt.after == "halt" and after_halt.fault
    assert "HOT" in after_halt.flags["j3"][0]
    names = {n for e in measurements for flags in e.flags.values() for n in flags}
    assert not names & {"NOT_OK", "SWR", "MOTION", "RAMP_END", "HOME_OK"}, names


# -- the registry ----------------------------------------------------------------------------

def test_the_registry_opens_the_driver_an_arm_file_names(ideal_driver):
    from seqrun.drivers.powercube import PowerCubeDriver
    from seqrun.service.connection import open_connection

    assert registry.driver_name(ARM) == "powercube" == registry.DEFAULT_DRIVER
    connection = open_connection(force_sim=True, clock=VirtualClock(), python_can=False)
    try:
        driver = registry.open_driver(ARM, connection)
        assert isinstance(driver, PowerCubeDriver) and isinstance(driver, ArmDriver)
        driver.close()
    finally:
        connection.close()
    assert isinstance(registry.open_driver(IDEAL, IdealBus(park())), IdealArm)


def test_an_unknown_driver_is_one_line_naming_the_known_ones():
    with pytest.raises(UserInputError, match=r"unknown arm driver 'canopen' \(known: "
                                             r"powercube\)"):
        registry.open_driver(ARM.model_copy(update={"driver": "canopen"}), None)


def test_a_logged_state_code_is_described_by_its_drivers_family(ideal_driver):
    """What a run folder's ``state`` columns say comes from the family that logged them
    (the report's CSV asks the registry, never PowerCube)."""
    assert registry.cycle_state(ARM, 0x11).describe() == "NOT_OK|MOTION"
    assert registry.cycle_state(None, 0).describe() == "OK"    # (no arm logged: PowerCube)
    assert registry.cycle_state(IDEAL, 1).describe() == "refuses"


def test_a_dry_run_starts_the_simulated_drives_where_the_arm_stands():
    """The offsets are applied by the driver family, once: Park in user degrees is the
    modules' encoder zero (the shipped arm's zero reference is Park)."""
    assert registry.simulator_positions(ARM, park()) == pytest.approx(
        dict.fromkeys(ARM.module_ids, 0.0), abs=1e-12)


def test_the_offsets_are_applied_in_one_place():
    """The user-degree <-> module-radian offset is the PowerCube family's, in one module
    (issue 25.1: it was applied in the arm description, the executor, the setpoint laws
    and the codec); the arm description only holds the offsets."""
    users = sorted(str(path.relative_to(ROOT)) for path in (ROOT / "seqrun").rglob("*.py")
                   if "offset_deg" in path.read_text(encoding="utf-8"))
    assert users == ["seqrun/arm/description.py", "seqrun/drivers/powercube/units.py"]
    from seqrun.arm.description import Joint

    assert not hasattr(Joint, "to_module_rad") and not hasattr(Joint, "to_user_deg")


def test_the_powercube_driver_confirms_home_by_reading_it_back():
    """Confirmed Halt, Reset and Home are the driver's (seqrun halt / reset, the session)."""
    from seqrun.service.connection import open_connection

    connection = open_connection(force_sim=True, clock=VirtualClock(), python_can=False)
    try:
        driver = registry.open_driver(ARM, connection)
        assert not driver.homed()           # freshly powered on
        home = driver.confirm("home")
        assert home.confirmed and home.command == "home" and driver.homed(), home.describe()
        halt = driver.confirm("halt")
        assert halt.confirmed and all(s.halted for s in halt.states.values())
        home = driver.confirm("home")       # halted: Home is not a Reset, not even sent
        assert not home.sent and not home.confirmed and "reset them first" in home.error
        assert "HALTED" in home.describe_unconfirmed()
        assert driver.confirm("reset").confirmed
        driver.close()
    finally:
        connection.close()


def test_the_powercube_driver_reads_which_arm_it_is_from_the_modules_serials():
    """The arm's identity is what its modules say (DefCubeSerial), read over the bus: two
    simulated arms are two identities, the same serials the same one."""
    from seqrun.clock import VirtualClock
    from seqrun.drivers.registry import open_driver
    from seqrun.service.connection import Connection
    from seqrun.sim.bus import SimBus

    identities = []
    for name, serials in (("a", {m: 500 + m for m in range(1, 8)}),
                          ("b", {m: 900 + m for m in range(1, 8)}),
                          ("c", {m: 500 + m for m in range(1, 8)})):
        clock = VirtualClock()
        bus = SimBus(channel=f"identity-{name}-{id(clock)}", clock=clock, serials=serials)
        driver = open_driver(ARM, Connection(bus, clock, False, "test"))
        try:
            identities.append(driver.identity())
        finally:
            driver.close()
            bus.shutdown()
    assert identities[0].by_module() == {m: str(500 + m) for m in range(1, 8)}
    assert identities[0].key == ",".join(f"{m}={500 + m}" for m in range(1, 8))
    assert identities[0] == identities[2] != identities[1]
