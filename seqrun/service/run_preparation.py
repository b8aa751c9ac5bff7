"""A run made ready, up to an open bus: what ``seqrun run`` does before it asks anything.

:func:`prepare_run` checks the options, loads the sequence (every problem in one pass,
as ``seqrun validate`` reports them), loads its arm, checks the sequence statically from
the assumed start (nothing is opened before that passes; a refusal is recorded in the
campaign) and opens the bus (the campaign's, python-can's configuration, else the
simulator). What follows — the operator's questions, the zero reference, the run in the
arm session — is the face's, through :class:`~seqrun.service.session.ArmSession`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from seqrun.errors import SeqrunError, SequenceInvalid, UserInputError

if TYPE_CHECKING:
    from seqrun.arm.description import ArmDescription
    from seqrun.sequence.loader import LoadedSequence
    from seqrun.service.arm_context import ArmContext
    from seqrun.service.connection import Connection

__all__ = ["PreparedRun", "RunInvalid", "RunRequest", "prepare_run", "run_folder"]


@dataclass
class RunRequest:
    """``seqrun run``'s options."""

    file: Path
    interface: str | None = None
    channel: str | None = None
    bitrate: int | None = None
    bus_kwargs: Sequence[str] = ()
    sim: bool = False
    sim_faults: Sequence[str] = ()
    speed: float = 1.0
    from_step: int = 1
    log_dir: Path | None = None
    arm_file: Path | None = None
    command_mode: str | None = None
    start: str | None = None
    started: bool = False
    virtual_time: bool = False
    project_dir: Path | None = None
    power_on_at: str | None = None
    #: In a campaign with several arms: the arm a sequence of one arm runs on.
    arm_id: str | None = None
    #: ``--param NAME=VALUE`` options: the sequence's parameters over their defaults.
    params: Sequence[str] = ()
    #: ``--yes``: a run nobody attends, refused before the bus is opened when a step needs
    #: a person (a signed confirm, a breakpoint, a hazardous step, given or derived).
    assume_yes: bool = False


@dataclass
class PreparedRun:
    """A run ready to go: the sequence, its arm (the arm file's offsets: the zero
    reference is decided on the bus) and the open connection (the caller closes it)."""

    loaded: LoadedSequence
    arm: ArmDescription
    connection: Connection
    #: The arm file the run names (its record says which).
    arm_path: Path = field(default_factory=Path)
    #: The sequence file as the operator named it.
    file: Path = field(default_factory=Path)
    #: The arm context the run was resolved in (its zero store, its headline).
    context: ArmContext | None = None
    #: The files used in place of shipped ones (arm, poses), as ``validate`` notes them.
    overrides: list = field(default_factory=list)
    #: The steps of class caution or hazardous as validated from the assumed start (step
    #: number -> HazardFinding): a hazardous one makes --yes refuse the run.
    hazards: dict = field(default_factory=dict)

    @property
    def arm_id(self) -> str | None:
        """The campaign's arm it runs on (``[arms.ID]``; None: a campaign of one arm)."""
        return self.context.arm_id if self.context is not None else None


class RunInvalid(SeqrunError):
    """The sequence is not valid from the assumed start: nothing was opened or sent."""

    def __init__(self, file: str, errors: list) -> None:
        super().__init__(f"{file}: invalid ({len(errors)} error{'s' * (len(errors) != 1)}); "
                         "nothing was sent")
        self.file = file
        self.errors = errors


def prepare_run(request: RunRequest) -> PreparedRun:
    """Check, load and validate the run of ``request``, then open its bus.

    :raises UserInputError: an option or file that cannot be used (one line).
    :raises SequenceInvalid: the sequence does not load (every error, as ``validate``).
    :raises RunInvalid: it loads but is not valid from the assumed start.
    """
    from seqrun.clock import VirtualClock
    from seqrun.sequence.loader import load_sequence
    from seqrun.steps.sequence_parameters import parse_options
    from seqrun.service import campaign_records
    from seqrun.service.arm_context import resolve_context
    from seqrun.service.checking import check_for_run, errors_before_bus, override_notes
    from seqrun.service.connection import parse_bus_kwargs, parse_faults

    r = request
    if not 0 < r.speed <= 1:
        raise UserInputError(f"--speed must lie in (0, 1], got {r.speed:g}")
    if r.command_mode not in (None, "ramp", "step"):
        raise UserInputError(f"--command-mode must be ramp or step, got '{r.command_mode}'")
    if not r.file.is_file():
        raise UserInputError(f"sequence file {r.file} not found")
    faults = parse_faults(list(r.sim_faults))
    extra = parse_bus_kwargs(list(r.bus_kwargs))
    given = parse_options(r.params)
    try:
        loaded = load_sequence(r.file, project_root=r.project_dir,
                               params=given)  # invalid -> no bus
    except SequenceInvalid as exc:
        # Every problem in one pass, exactly as `seqrun validate` reports them: the steps
        # that are valid on their own are still checked against the arm.
        errors = errors_before_bus(r.file, exc.errors, start=r.start, arm_file=r.arm_file,
                                   started=r.started, speed=r.speed,
                                   project_dir=r.project_dir, params=given)
        campaign_records.refuse_unloadable(r.file, r.project_dir, errors, r.log_dir)
        raise SequenceInvalid(errors) from None
    # The arm context: the sequence's campaign and arm, the bus (command line, else the
    # campaign's, else python-can's configuration, else the simulator).
    # One arm of several: its own arm file (from seqrun.toml), as the console runs it.
    context = resolve_context(project=loaded.project, arm_file=r.arm_file,
                              arm_path=loaded.arm_path if r.arm_id is None else None,
                              interface=r.interface, channel=r.channel, bitrate=r.bitrate,
                              bus_kwargs=extra, sim=r.sim, arm_id=r.arm_id)
    arm_path = context.arm_path
    arm = context.arm
    if r.power_on_at is not None:
        arm.power_off_pose(r.power_on_at)  # one of the arm's power-off poses
    if not 1 <= r.from_step <= len(loaded.steps):
        raise UserInputError(f"--from {r.from_step}: the sequence has steps "
                             f"1-{len(loaded.steps)}")
    # Static validation before the bus is even opened; the executor validates again from
    # the measured state before the first motion.
    static = check_for_run(loaded, arm, r.start, r.started, r.from_step)
    if static.errors:
        campaign_records.refuse(loaded, arm_path, static.errors, r.log_dir, arm=arm,
                                arm_id=context.arm_id)
        raise RunInvalid(loaded.file, list(static.errors))
    if r.assume_yes:   # (derived hazard classes are known from here on)
        from seqrun.service.attended import yes_refusal

        refusal = yes_refusal(loaded.steps, static.hazards)
        if refusal is not None:
            raise UserInputError(refusal)
    if r.virtual_time and not context.bus.is_simulator:
        raise UserInputError("--virtual-time needs the simulator")
    if not r.virtual_time:   # (virtual time is the simulator, asked for)
        context.refuse_private_simulator("run")
    for fault in faults:  # the simulated arm has the arm file's modules
        if fault.module is not None and fault.module not in arm.module_ids:
            raise UserInputError(f"--sim-fault '{fault.spec}': the arm has no module "
                                 f"{fault.module} (modules {', '.join(map(str, arm.module_ids))})")
    from seqrun.service.simulated_part import simulated_part

    connection = context.open_connection(
        part=simulated_part(loaded.steps, loaded.project),
        faults=faults, clock=VirtualClock() if r.virtual_time else None,
        power_on_pose=r.power_on_at.lower() if r.power_on_at else None, live=True)
    if r.virtual_time and not connection.is_simulator:
        connection.close()
        raise UserInputError("--virtual-time needs the simulator")
    if r.power_on_at is not None and not connection.is_simulator:
        connection.close()
        raise UserInputError("--power-on-at applies to the built-in simulator (seqrun sim "
                             "serve has its own)")
    return PreparedRun(loaded, arm, connection, Path(arm_path), r.file, context,
                       override_notes(loaded, Path(arm_path)), dict(static.hazards))


def run_folder(loaded: LoadedSequence, log_dir: Path | None) -> Path:
    """The run's folder (``--log-dir``, else a new one in the campaign's runs/); a used
    ``--log-dir`` gets a new folder inside. An unusable one: UserInputError."""
    from seqrun.service import campaign_records
    from seqrun.service.runlog import prepare_run_folder

    try:
        return prepare_run_folder(log_dir, loaded.name, campaign_records.runs_dir(loaded))
    except OSError as exc:
        raise UserInputError(f"cannot create the run folder "
                             f"{log_dir or campaign_records.runs_dir(loaded)}: "
                             f"{exc.strerror or exc}") from None
