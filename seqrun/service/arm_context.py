"""Which arm a command talks to: the arm context, resolved once.

Every command and face (``run``, ``validate``, ``status``, ``halt``, ``reset``, ``pose``,
``zero``, ``console``, ``runs``) builds one :class:`ArmContext` with :func:`resolve_context`
and takes everything from it: the campaign, the arm file (and so its tools), the pose
search path, the folder run logs go to, and the bus. Nothing else decides these. The zero
reference follows from the bus: it belongs to the physical arm found there, named by the
serial numbers its modules report (:mod:`seqrun.service.zero`, one store per arm on this
machine, shared by every campaign). The order, each time the same:

- campaign: ``--project DIR``, else the campaign of the sequence (for ``run``), else the
  nearest ``seqrun.toml`` above the current directory, else the nearest folder with
  ``arms/`` or ``poses/`` (the checkout), else the current directory;
- arm file: ``--arm FILE``, else the sequence's ``arm:``, else the campaign's
  ``[campaign] arm``, else the shipped ``lwa3``;
- bus: the command line (``-i/-c/-b/--bus-kwargs``, or ``--sim``), else the campaign's
  ``[bus]``, else python-can's configuration (``CAN_INTERFACE``, ``~/.canrc``, ...), else
  the built-in simulator.

A command never acts on a private simulator while the operator means an arm
(:meth:`ArmContext.refuse_private_simulator`): with no bus configured, ``halt`` and
``status`` act through the seqrun run or console that is live on this machine (its
control socket), and with nothing live they say there is no arm (exit 2).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

from seqrun.errors import UserInputError

if TYPE_CHECKING:
    import numpy as np

    from seqrun.arm.description import ArmDescription
    from seqrun.drivers.base import ArmDriver
    from seqrun.sequence.campaign_config import BasePose, BusSection
    from seqrun.sequence.project import Project
    from seqrun.service.simulated_part import SimulatedPart
    from seqrun.service.bus_claim import Holder
    from seqrun.service.connection import Connection

__all__ = ["ArmContext", "BusChoice", "NoArm", "SIMULATOR_CLAIM_INTERFACE", "arms_by_arm_file",
           "campaign_folders", "load_arm_file", "one_arm_file", "refuse_shared_buses",
           "resolve_context", "resolve_contexts"]

#: The claim a run or console on the built-in simulator holds, so that ``seqrun halt`` and
#: ``seqrun status`` in another terminal find it (its channel names the process).
SIMULATOR_CLAIM_INTERFACE = "seqrun-sim"


class NoArm(UserInputError):
    """No bus is configured and no seqrun run or console is live: there is no arm to act on
    (exit 2; never a private simulator's "confirmed")."""


@dataclass(frozen=True)
class BusChoice:
    """The bus a command talks to, and who chose it."""

    interface: str | None = None
    channel: str | None = None
    bitrate: int | None = None
    kwargs: Mapping[str, Any] = field(default_factory=dict)
    #: ``--sim``: the operator asked for the built-in simulator.
    force_sim: bool = False
    #: Who chose it: "--sim", "the command line", "<campaign>/seqrun.toml",
    #: "python-can's configuration" or "nothing configured".
    source: str = "nothing configured"
    #: python-can's merged configuration ({}: the built-in simulator).
    config: Mapping[str, Any] = field(default_factory=dict)

    @property
    def is_simulator(self) -> bool:
        from seqrun.service.connection import SIM_INTERFACE

        return (self.force_sim or not self.config.get("interface")
                or self.config.get("interface") == SIM_INTERFACE)

    @property
    def defaulted_to_simulator(self) -> bool:
        """The built-in simulator because nothing names a bus (not asked for)."""
        from seqrun.service.connection import SIM_INTERFACE

        return self.is_simulator and not self.force_sim and self.interface != SIM_INTERFACE

    @property
    def key(self) -> tuple[str, str] | None:
        """The claim key of a bus other processes can reach; None for the simulator."""
        from seqrun.service.connection import bus_key

        return None if self.is_simulator else bus_key(self.config)

    def describe(self) -> str:
        if self.is_simulator:
            why = "--sim" if self.force_sim else f"from {self.source}" \
                if self.source != "nothing configured" else "no bus configured"
            return f"the built-in simulator ({why}): no hardware is moved"
        from seqrun.service.connection import bus_text

        return f"{bus_text(self.config)} (from {self.source})"


@dataclass
class ArmContext:
    """The arm, its files and its bus, as one command sees them (see the module doc)."""

    project: Project
    pose_path: Any
    runs_dir: Path
    response_timeout_ms: float | None = None
    #: Simulator fault specs (``--sim-fault``), parsed when the bus opens.
    faults: Sequence[str] = ()
    #: ``--arm``, else the arm the sequence names (None: the campaign's).
    given_arm: Path | None = None
    #: The bus options as given (resolved on first use: ``runs`` needs none).
    bus_options: Mapping[str, Any] = field(default_factory=dict)
    _arm: ArmDescription | None = field(default=None, repr=False)
    #: The arm's id in a campaign with several arms (``[arms.B]``: "B"); None: the one arm.
    arm_id: str | None = None
    #: Its ``[arms.ID]`` table's arm reference and bus (None: the one-arm format's).
    arm_ref: str | None = None
    bus_section: BusSection | None = None
    #: Where its base frame stands in the facility frame (None: the facility frame).
    base: BasePose | None = None

    @property
    def part(self) -> str:
        """This arm's part of a run folder (its subfolder; "" for the one arm)."""
        return self.arm_id or ""

    def base_transform(self) -> np.ndarray:
        """4x4: the arm's base frame in the common facility frame (millimetres)."""
        from seqrun.arm.between_arms import base_of

        return base_of(self.base)

    # ------------------------------------------------------------------ the arm
    @cached_property
    def arm_path(self) -> Path:
        """The arm file: ``--arm``, else the sequence's, else the campaign's, else the
        shipped one."""
        if self.given_arm is not None:
            return Path(self.given_arm).resolve()
        return self.project.arm_path(self.arm_ref)

    @cached_property
    def bus(self) -> BusChoice:
        return resolve_bus(self.project, section=self.bus_section, **self.bus_options)

    @property
    def arm(self) -> ArmDescription:
        """The arm file, loaded once."""
        if self._arm is None:
            if not self.arm_path.is_file():
                raise UserInputError(f"arm file {self.arm_path} not found "
                                     "(give one with --arm FILE)")
            from seqrun.arm.description import load_arm

            self._arm = load_arm(self.arm_path)
        return self._arm

    @property
    def tools(self) -> Any:
        """The arm file's tools (the arm file is the one place a tool is defined)."""
        return self.arm.tools

    # ------------------------------------------------------------------ what it says
    def arm_text(self) -> str:
        from seqrun.formatting import terminal_text

        where = _shown(self.arm_path)
        named = f"arm {self.arm_id}: " if self.arm_id else ""
        return terminal_text(f"{named}arm '{self.arm.name}' ({where})")

    def headline(self, connection: Connection | None = None) -> str:
        """The first line of every command: which arm, on which bus, chosen by whom."""
        if connection is None:
            return f"{self.arm_text()} on {self.bus.describe()}"
        chosen = "" if connection.is_simulator else f" (from {self.bus.source})"
        return f"{self.arm_text()} on {connection.description}{chosen}"

    # ------------------------------------------------------------------ the bus
    def live_controllers(self) -> list[Holder]:
        """The seqrun runs and consoles live on this machine (this user's), serving a
        control socket, whatever they drive."""
        from seqrun.service.control_socket import live_owners

        return live_owners()

    @property
    def campaign_key(self) -> str:
        """This campaign as a live holder's record names it (its folder, resolved)."""
        return str(Path(self.project.root).resolve())

    def own_controllers(self, live: Sequence[Holder]) -> list[Holder]:
        """Those of ``live`` that drive this arm: started in this campaign, as this arm id.
        (Another folder's run, or another arm of this campaign, is not this arm.)"""
        return [h for h in live if h.campaign == self.campaign_key and h.arm_id == self.arm_id]

    def refuse_private_simulator(self, what: str) -> None:
        """A command about to act on "the arm" (``what``: "halt", "reset", "run", ...)
        that would get a private simulator the operator did not ask for, while a seqrun
        run or console drives a real bus on this machine (or this arm, on whatever bus):
        :class:`UserInputError` naming it. Another process's built-in simulator is no arm
        anybody means: it never blocks."""
        if not self.bus.defaulted_to_simulator:
            return
        live = [h for h in self.live_controllers()
                if h.reach or h in self.own_controllers([h])]
        if live:
            raise UserInputError(
                f"no bus configured, and {_list(live)} live on this machine: '{what}' would "
                "act on a private simulator, not the arm it drives; use that arm through "
                "it, name a bus with -i/-c, or give --sim for a private simulator")

    def open_connection(self, *, claim: bool = True, transient: bool = False,
                        live: bool = False, part: SimulatedPart | None = None,
                        **extra: Any) -> Connection:
        """Open the bus (:func:`seqrun.service.connection.open_connection`). ``live`` (a
        run, a console): on the built-in simulator the process also claims a name of its
        own and serves its control socket there, so that ``seqrun halt`` finds it.
        ``part``: the part between the simulated gripper's jaws (a run: the sequence's,
        :func:`seqrun.service.simulated_part.simulated_part`; default the campaign's)."""
        from seqrun.service.connection import open_connection, parse_faults, response_timeout_s
        from seqrun.service.simulated_part import campaign_part, switch_given

        arm = self.arm
        response_timeout_s(arm, self.response_timeout_ms)  # a bad value: before the bus
        b = self.bus
        connection = open_connection(interface=b.interface, channel=b.channel,
                                     bitrate=b.bitrate, bus_kwargs=dict(b.kwargs),
                                     force_sim=b.force_sim,
                                     faults=extra.pop("faults", None)
                                     or parse_faults(list(self.faults)),
                                     default_bitrate=arm.can.bitrate, claim=claim,
                                     transient=transient,
                                     # the simulator: the arm file's modules on the bus
                                     sim_modules=extra.pop("sim_modules", None)
                                     or arm.present_module_ids, **extra)
        if arm.gripper is not None and connection.is_simulator:
            # the built-in simulator carries the arm file's gripper, with the part the dry
            # run places (seqrun.service.simulated_part); a part given by hand wins
            sim = getattr(connection.bus, "arm", None)
            if sim is not None and sim.gripper_id is None:
                part_mm = sim.options.gripper_part_mm
                if not switch_given(b.kwargs):
                    declared = part if part is not None else campaign_part(self.project)
                    if declared is not None:
                        part_mm = declared.width_mm
                        connection.description += f"; {declared.describe()}"
                sim.add_gripper(arm.gripper.module, part_mm)
        if live and connection.is_simulator and connection.claim is None:
            from seqrun.service.bus_claim import claim_bus

            try:
                held = claim_bus(SIMULATOR_CLAIM_INTERFACE,
                                 f"pid{os.getpid()}-{id(connection):x}")
            except Exception:
                connection.close()
                raise
            # A name nobody else claims: its lock file goes with it (no litter per run).
            lock = held.directory / f"{held.stem}.lock"
            held.on_release(lambda: lock.unlink(missing_ok=True))
            connection.claim = held
        if connection.claim is not None:
            # which arm: for 'seqrun halt' and 'seqrun status' in another terminal
            connection.claim.describe_arm(campaign=self.campaign_key, arm_id=self.arm_id,
                                          reach=connection.reach)
        return connection

    def open_arm(self, *, claim: bool = True, transient: bool = True
                 ) -> tuple[Connection, ArmDriver]:
        """The bus and the arm's driver on it: ``(connection, driver)``."""
        connection = self.open_connection(claim=claim, transient=transient)
        return connection, self._driver(connection, self.arm)

    def open_arm_for_reading(self) -> tuple[Connection, ArmDriver, ArmDescription, str]:
        """As :meth:`open_arm`, the driver converting with the zero reference in force (the
        record's, as ``seqrun status`` reads; never asked: nothing moves), not the arm
        file's default offsets: ``(connection, driver, arm at that zero, zero text)``."""
        from seqrun.service.zero import zero_for_reading

        connection = self.open_connection(transient=True)
        try:
            arm, text = zero_for_reading(connection, self.arm)
            driver = self._driver(connection, arm)
        except BaseException:
            connection.close()
            raise
        return connection, driver, arm, text

    def _driver(self, connection: Connection, arm: ArmDescription) -> ArmDriver:
        """``arm``'s driver on ``connection``, with this context's response timeout."""
        from seqrun.drivers.registry import open_driver
        from seqrun.service.connection import response_timeout_s

        timeout = response_timeout_s(arm, self.response_timeout_ms)
        return open_driver(arm, connection, response_timeout_s=timeout)


def _shown(path: Path) -> str:
    """A path inside the current directory relative to it, else whole."""
    path = Path(path)
    try:
        return str(path.resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


def _list(holders: Sequence[Holder]) -> str:
    from seqrun.formatting import terminal_text

    names = [f"seqrun pid {h.pid} ({terminal_text(h.command)})" for h in holders]
    return names[0] + " is" if len(names) == 1 else ", ".join(names) + " are"


def resolve_bus(project: Project | None, *, interface: str | None = None,
                channel: str | None = None, bitrate: int | None = None,
                bus_kwargs: Sequence[str] | Mapping[str, Any] = (), sim: bool = False,
                section: BusSection | None = None) -> BusChoice:
    """The bus of a command: command line, else the campaign's ``[bus]`` (``section``: an
    arm's ``[arms.ID]`` bus instead), else python-can's configuration, else the built-in
    simulator (see the module doc). An arm of a campaign with several arms whose bus names
    no interface gets a simulated bus of its own (python-can's configuration names one bus,
    not one per arm)."""
    from seqrun.service.connection import parse_bus_kwargs, resolve_config

    extra = dict(bus_kwargs) if isinstance(bus_kwargs, Mapping) else \
        parse_bus_kwargs(list(bus_kwargs))
    if sim:
        if interface or channel:
            raise UserInputError("--sim cannot be combined with -i/-c")
        _check_simulator_switches(extra)
        return BusChoice(None, None, bitrate, extra, True, "--sim", {})
    source = "the command line"
    config = getattr(project, "config", None)
    chosen = section if section is not None else \
        (config.bus if config is not None else None)
    if section is not None and not (interface or channel or bitrate or extra) \
            and section.interface is None:
        # an arm of several with no bus of its own: its own simulated bus
        extra = dict(section.kwargs)
        _check_simulator_switches(extra)
        path = getattr(project, "config_path", None)
        return BusChoice(None, None, section.bitrate, extra, False,
                         _shown(path) if path else "seqrun.toml", {})
    if not (interface or channel or bitrate or extra) and chosen is not None \
            and chosen.interface is not None:
        b = chosen
        interface, channel, bitrate, extra = b.interface, b.channel, b.bitrate, dict(b.kwargs)
        path = getattr(project, "config_path", None)
        source = _shown(path) if path else "seqrun.toml"
    elif not (interface or channel or bitrate or extra):
        source = "python-can's configuration"
    resolved = resolve_config(interface, channel, bitrate, extra)
    if not resolved:
        source = "nothing configured" if source != "the command line" else source
        _check_simulator_switches(extra)
    return BusChoice(interface, channel, bitrate, extra, False, source, resolved)


def _check_simulator_switches(extra: Mapping[str, Any]) -> None:
    """``--bus-kwargs`` for the built-in simulator: its switches only, well typed (one
    line before anything else is decided)."""
    from seqrun.sim.options import SWITCHES, module_options

    if others := sorted(set(extra) - SWITCHES):
        raise UserInputError(f"--bus-kwargs {', '.join(others)}: the built-in simulator "
                             "takes only its switches (e.g. home_ok_at_power_on=true); "
                             "name an interface with -i")
    try:
        module_options(extra)
    except ValueError as exc:
        raise UserInputError(f"--bus-kwargs: {exc}") from None


def resolve_context(*, project_dir: Path | None = None, project: Project | None = None,
                    arm_file: Path | None = None, arm_path: Path | None = None,
                    poses_dir: Path | None = None, log_dir: Path | None = None,
                    interface: str | None = None, channel: str | None = None,
                    bitrate: int | None = None,
                    bus_kwargs: Sequence[str] | Mapping[str, Any] = (), sim: bool = False,
                    response_timeout_ms: float | None = None,
                    faults: Sequence[str] = (), arm_id: str | None = None) -> ArmContext:
    """The one place the arm context is decided (see the module doc).

    :param project: the campaign already found (a loaded sequence's); else ``project_dir``
        or the campaign of the current directory.
    :param arm_file: ``--arm``; ``arm_path``: the arm the sequence names (``run``).
    :param arm_id: in a campaign with several arms (``[arms.ID]``), which one (None: the
        only one; refused when there are several).
    :raises UserInputError: a campaign, arm or bus option that cannot be used.
    """
    project, pose_path, runs = campaign_folders(project_dir=project_dir, project=project,
                                                poses_dir=poses_dir, log_dir=log_dir)
    if arm_file is not None and not Path(arm_file).is_file():
        raise UserInputError(f"arm file {arm_file} not found (give one with --arm FILE)")
    given = arm_file if arm_file is not None else arm_path
    entry = _arm_entry(project, arm_id)
    return ArmContext(project, pose_path, runs, response_timeout_ms, tuple(faults),
                      Path(given) if given is not None else None,
                      {"interface": interface, "channel": channel, "bitrate": bitrate,
                       "bus_kwargs": bus_kwargs, "sim": sim},
                      arm_id=entry[0] if entry else None,
                      arm_ref=entry[1].arm if entry else None,
                      bus_section=entry[1].bus if entry else None,
                      base=entry[1].base if entry else None)


def campaign_folders(*, project_dir: Path | None = None, project: Project | None = None,
                     poses_dir: Path | None = None, log_dir: Path | None = None
                     ) -> tuple[Project, Any, Path]:
    """What every arm of a campaign shares: ``(campaign, pose search path, runs folder)``
    (``poses_dir``: ``--poses-dir``; ``log_dir``: a run folder's parent given on the command
    line). The commands that need no arm (``seqrun runs``, ``pose list``) stop here."""
    from seqrun.defaults import DEFAULT_POSES_DIR

    if project is None:
        from seqrun.service.campaigns import campaign_here

        project = campaign_here(project_dir)
    pose_path: Any = project.pose_path
    if poses_dir is not None and Path(poses_dir) != DEFAULT_POSES_DIR:
        pose_path = Path(poses_dir)
    return project, pose_path, Path(log_dir) if log_dir is not None else project.runs_dir


def one_arm_file(project: Project, arm_id: str | None) -> Path | None:
    """The arm file of a command about one arm that needs no bus (a sequence of one arm
    validated, fk, ik) in a campaign with several arms: arm ``arm_id``'s; none named, the
    one arm file every arm shares. None: a campaign of one arm (the sequence's own arm
    file, the campaign's).

    :raises UserInputError: an unknown id, or no id while the arms' arm files differ
        (which arm is it for?).
    """
    if arm_id is not None:
        return resolve_context(project=project, arm_id=arm_id).arm_path
    files = arms_by_arm_file(project)
    if len(files) > 1:
        raise UserInputError(
            f"{project.describe()} has arms {', '.join(campaign_arm_ids(project))} with "
            "different arm files ("
            + ", ".join(f"{', '.join(ids)}: {_shown(p)}" for p, ids in files.items())
            + "): name the arm (--arm-id ID)")
    return None


def arms_by_arm_file(project: Project) -> dict[Path, list[str]]:
    """The arm files of a campaign's several arms, each with the ids of the arms that have
    it ({} for a campaign of one arm, even one written as a single ``[arms.ID]``)."""
    ids = campaign_arm_ids(project)
    if len(ids) < 2:
        return {}
    by_file: dict[Path, list[str]] = {}
    for arm_id in ids:
        by_file.setdefault(resolve_context(project=project, arm_id=arm_id).arm_path,
                           []).append(arm_id)
    return by_file


def load_arm_file(path: Path, arm_id: str | None = None) -> ArmDescription:
    """The arm file ``path``; for the default (``arms/lwa3.yaml``) where there is none, the
    campaign's arm here (seqrun.toml), else the shipped one. In a campaign with several
    arms: arm ``arm_id``'s (none named: the one every arm shares; UserInputError when they
    differ, as for ``--arm`` with ``arm_id``)."""
    from seqrun.defaults import DEFAULT_ARM
    from seqrun.service.campaigns import campaign_of

    if arm_id is not None and path != DEFAULT_ARM:
        raise UserInputError("--arm-id names the arm file (seqrun.toml's [arms.ID]): leave "
                             "out --arm")
    if path == DEFAULT_ARM:
        project = campaign_of(Path.cwd())
        if arm_id is not None or len(campaign_arm_ids(project)) > 1:
            path = one_arm_file(project, arm_id) or project.arm_path(None)
        elif not path.is_file():
            path = project.arm_path(None)
    if not path.is_file():
        raise UserInputError(f"arm file {path} not found (give one with --arm FILE)")
    from seqrun.arm.description import load_arm  # pydantic: only for commands that read one

    return load_arm(path)


def campaign_arm_ids(project: Project) -> tuple[str, ...]:
    """The arm ids of a campaign with several arms (``[arms.ID]``); () for the one arm."""
    config = getattr(project, "config", None)
    return config.arm_ids if config is not None else ()


def _arm_entry(project: Project, arm_id: str | None) -> tuple[str, Any] | None:
    ids = campaign_arm_ids(project)
    if not ids:
        if arm_id is not None:
            raise UserInputError(f"arm '{arm_id}': {project.describe()} names no arms "
                                 "([arms.ID] in seqrun.toml); leave the arm id out")
        return None
    if arm_id is None:
        if len(ids) > 1:
            raise UserInputError(f"{project.describe()} has arms {', '.join(ids)}: name "
                                 "one (--arm-id ID)")
        arm_id = ids[0]
    if arm_id not in ids:
        raise UserInputError(f"unknown arm '{arm_id}': {project.describe()} has arms "
                             f"{', '.join(ids)}")
    assert project.config is not None
    return arm_id, project.config.arms[arm_id]


def resolve_contexts(*, arm_ids: Sequence[str] | None = None, **options: Any
                     ) -> list[ArmContext]:
    """Every arm of the campaign (``arm_ids``: only these, in the campaign's order), each
    resolved by :func:`resolve_context`; a one-arm campaign gives its one context.

    :raises UserInputError: an unknown arm id, or one bus from the command line (-i/-c)
        for several arms (each has its own: name one arm).
    """
    project = options.pop("project", None)
    if project is None:
        from seqrun.service.campaigns import campaign_here

        project = campaign_here(options.pop("project_dir", None))
    else:
        options.pop("project_dir", None)
    ids = campaign_arm_ids(project)
    if not ids:
        if arm_ids:
            _arm_entry(project, arm_ids[0])  # says why
        return [resolve_context(project=project, **options)]
    wanted = list(dict.fromkeys(arm_ids)) if arm_ids else list(ids)
    for name in wanted:
        if name not in ids:
            _arm_entry(project, name)
    wanted = [name for name in ids if name in wanted]
    if len(wanted) > 1 and (options.get("interface") or options.get("channel")):
        raise UserInputError("-i/-c name one bus, and each arm of this campaign has its own: "
                             "name one arm (--arm-id ID)")
    if len(wanted) > 1 and options.get("arm_file") is not None:
        raise UserInputError("--arm names one arm file, and each arm of this campaign has its "
                             "own: name one arm (--arm-id ID)")
    return [resolve_context(project=project, arm_id=name, **options) for name in wanted]


def refuse_shared_buses(project: Project, contexts: Sequence[ArmContext]) -> None:
    """Two arms of one campaign on one bus (the same server and channel, however its host
    is spelt: ``localhost`` and ``127.0.0.1`` are one server): :class:`UserInputError`
    naming both (seqrun.toml's own check compares the text only)."""
    seen: dict[tuple[str, str], str | None] = {}
    for context in contexts:
        if context.bus_section is None or context.bus_section.interface is None:
            continue   # a simulated bus of its own
        key = context.bus.key
        if key is None:
            continue
        if key in seen:
            from seqrun.service.bus_claim import bus_name

            path = getattr(project, "config_path", None)
            where = f"{_shown(path)}: " if path else ""
            raise UserInputError(
                f"{where}arms {seen[key]} and {context.arm_id} are on the same bus "
                f"({bus_name(*key)}, however its host is spelt): one controller per bus; "
                "give each arm a bus of its own")
        seen[key] = context.arm_id
