"""Pieces every command shares: common options and the one user-error boundary."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, NoReturn, Optional

import typer

# Exit codes have one definition (re-exported for the commands).
from seqrun.defaults import EXIT_FAULT, EXIT_INVALID, EXIT_OK, EXIT_USAGE  # noqa: F401
from seqrun.errors import Refused, SequenceInvalid, UserInputError
# The arm file and the poses a command reads (the campaign's, else the shipped ones).
from seqrun.service.arm_context import load_arm_file  # noqa: F401
from seqrun.service.campaigns import pose_search_path  # noqa: F401

#: The help says what load_arm_file really does with the default (not "arms/lwa3.yaml").
ArmOption = Annotated[Path, typer.Option(
    "--arm", metavar="FILE", show_default=False,
    help="Arm file (default: ./arms/lwa3.yaml if there is one, else the arm of the campaign "
         "here (its seqrun.toml), else the shipped lwa3).")]
#: An arm file only where one is given (None: the command finds the campaign's).
ArmFileOption = Annotated[Optional[Path], typer.Option(
    "--arm", metavar="FILE", help="Arm file (default: the arm of the campaign here (its "
                                  "seqrun.toml), else the shipped lwa3).")]
#: The campaign of the current directory unless one is given.
CampaignOption = Annotated[Optional[Path], typer.Option(
    "--project", metavar="DIR", help="Campaign folder (default: the one holding the current "
                                     "directory).")]
#: ``--arm-id ID``: in a campaign with several arms ([arms.ID]), the one arm a command of one
#: arm acts on (its arm file, bus and zero); the commands of every arm take ArmIdOption.
OneArmOption = Annotated[Optional[str], typer.Option(
    "--arm-id", metavar="ID", help="In a campaign with several arms ([arms.ID] in "
                                   "seqrun.toml): the arm.")]
PosesDirOption = Annotated[Path, typer.Option(
    "--poses-dir", metavar="DIR", help="Directory of pose files (<name>.yaml).")]


def fail(message: str, code: int = EXIT_USAGE) -> NoReturn:
    """One line on stderr and the exit code; the user never sees a traceback."""
    typer.echo(f"error: {message}", err=True)
    raise typer.Exit(code)


def validate_exit_code(static_valid: bool, dry_run_exit: int | None, rehearsed: bool) -> int:
    """``seqrun validate``'s exit code: 1 for a file that is not valid (its static checks,
    or a dry run that fails on a healthy simulated arm); a dry run ended by a rehearsed
    ``--sim-fault`` exits as ``seqrun run`` would have (3: aborted by a fault), so that 1
    always means "invalid" (README "Exit codes")."""
    if not static_valid:
        return EXIT_INVALID
    if not dry_run_exit:
        return EXIT_OK
    return EXIT_FAULT if rehearsed and dry_run_exit == EXIT_FAULT else EXIT_INVALID


@contextmanager
def user_errors() -> Iterator[None]:
    """Turn the user's mistakes (bad input, invalid files) into messages and exit codes."""
    try:
        yield
    except (UserInputError, Refused) as exc:  # Refused: the bus is another seqrun's
        fail(str(exc))
    except OSError as exc:  # a path the system refuses (name too long, permission, ...)
        fail(f"{exc.filename}: {exc.strerror or exc}" if exc.filename else str(exc))
    except SequenceInvalid as exc:
        for error in exc.errors:
            typer.echo(f"error: {error}", err=True)
        raise typer.Exit(EXIT_INVALID) from None


# Bus selection, shared by every command that talks to the arm (python-can's own flags).
InterfaceOption = Annotated[Optional[str], typer.Option(
    "-i", "--interface", help="python-can interface (socketcan, ixxat, pcan, socketcand, ...). "
                              "Default: python-can's configuration, else the simulator.")]
ChannelOption = Annotated[Optional[str], typer.Option("-c", "--channel", help="CAN channel.")]
BitrateOption = Annotated[Optional[int], typer.Option(
    "-b", "--bitrate", help="Bit rate in bit/s (default: the arm file's).")]
BusKwargsOption = Annotated[Optional[list[str]], typer.Option(
    "--bus-kwargs", metavar="KEY=VALUE", help="Extra python-can bus arguments (repeatable).")]
SimOption = Annotated[bool, typer.Option("--sim", help="Force the built-in simulator.")]
ResponseTimeoutOption = Annotated[Optional[float], typer.Option(
    "--response-timeout-ms", metavar="MS",
    help="How long to wait for each module's answer (default: $SEQRUN_RESPONSE_TIMEOUT_MS, "
         "else the arm file's can.response_timeout_s, 50 ms).")]


#: ``--zero-confirmed`` of a command that may drive several arms (repeatable):
#: ``POSE`` for every arm, ``ID=POSE`` for one (:func:`seqrun.service.zero.confirmed_per_arm`).
ZeroConfirmedPerArmOption = Annotated[Optional[list[str]], typer.Option(
    "--zero-confirmed", metavar="[ID=]POSE", help="Answer 'does the arm stand in POSE?' "
    "after a power-on without asking: the operator's word that the arm stands in the "
    "recorded power-off pose POSE (a different record refuses to start; --yes never "
    "answers it). With several arms: ID=POSE for arm ID (repeatable), a bare POSE for "
    "every arm.")]


def zero_confirmed_of(values: list[str] | None, arm_ids: list[str | None]
                      ) -> dict[str | None, str]:
    """``--zero-confirmed`` per arm (one line and exit 2 on a bad value)."""
    from seqrun.service.zero import confirmed_per_arm

    with user_errors():
        return confirmed_per_arm(values or [], arm_ids)
