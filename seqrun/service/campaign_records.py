"""What a run leaves in its campaign: the run folder's location, the record of a run (and
of one refused before it started), the zero-reference record of a power_off step."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

from seqrun.service.records import write_record, write_refusal
from seqrun.service.runlog import prepare_run_folder


def runs_dir(loaded: Any) -> Path:
    project = getattr(loaded, "project", None)
    return project.runs_dir if project is not None else Path("runs")


def _errors(errors: list) -> list[dict]:
    return [e.as_dict() if hasattr(e, "as_dict") else {"message": str(e)} for e in errors]


def refuse(loaded: Any, arm_path: Path, errors: list, log_dir: Path | None,
           arm: Any = None, arm_id: str | None = None) -> None:
    """A run refused by validation leaves a short record (best effort: the refusal itself
    is what the operator must see, a full disk must not hide it)."""
    try:  # a --log-dir that holds a run gets a new folder inside: evidence is never overwritten
        folder = prepare_run_folder(log_dir, loaded.name, runs_dir(loaded))
        write_refusal(folder, sequence=loaded.name, file=str(loaded.file),
                      errors=_errors(errors), loaded=loaded, arm_path=Path(arm_path),
                      arm=arm, arm_id=arm_id)
    except OSError:
        pass


def not_started(loaded: Any, arm_path: Path, log_dir: Path | None, message: str, *,
                arm: Any = None, bus: str | None = None, exit_code: int = 130,
                arm_id: str | None = None) -> None:
    """The record of a run that ended at a question before it started (declined, or a
    signal): nothing was sent. Best effort, as a refusal."""
    try:
        folder = prepare_run_folder(log_dir, loaded.name, runs_dir(loaded))
        write_refusal(folder, sequence=loaded.name, file=str(loaded.file), errors=[],
                      loaded=loaded, arm_path=Path(arm_path), bus=bus, arm=arm,
                      exit_code=exit_code, status="aborted", message=message,
                      arm_id=arm_id)
    except OSError:
        pass


def refuse_unloadable(file: Path, project_dir: Path | None, errors: list,
                      log_dir: Path | None) -> None:
    """The record of a sequence that could not even be loaded (its own errors)."""
    from seqrun.service.campaigns import campaign_of

    try:
        project = campaign_of(Path(file).resolve(), project_dir)
        folder = prepare_run_folder(log_dir, Path(file).stem, project.runs_dir)
        write_refusal(folder, sequence=Path(file).stem, file=str(file),
                      errors=_errors(errors))
    except Exception:  # the refusal is reported on the terminal either way
        pass


def record_run(folder: Path, loaded: Any, arm_path: Path, bus: str, zero: Any,
               arm: Any = None, overrides: list | None = None,
               arm_id: str | None = None) -> dict:
    """The run's record.json and inputs/: the bytes validated (of ``loaded`` and
    ``arm``), never the files read again. Raises OSError (a full disk)."""
    return write_record(folder, loaded=loaded, arm_path=Path(arm_path), bus=bus,
                        zero=zero.as_dict() if zero is not None else None, arm=arm,
                        overrides=[str(n) for n in overrides or ()], arm_id=arm_id)


def zero_recorder(store: Any, arm: Any, loaded: Any) -> Callable[[str], str]:
    """What the ``power_off`` step calls: record the pose for the next power-on, in the
    connected arm's own store (:class:`~seqrun.service.zero.ZeroStore`)."""

    def record(pose: str) -> str:
        from seqrun.errors import RunAborted, UserInputError

        try:
            entry = store.set_record(pose, by=Path(str(loaded.file)).name,
                                     joints_deg=arm.power_off_joints_deg(pose),
                                     arm_name=arm.name)
        except UserInputError as exc:  # (a folder this user may not write): the step fails
            raise RunAborted("power_off", f"power_off: {exc}; the zero reference of the "
                                          "next power-on is NOT recorded") from None
        return f"{entry.describe()} ({store.path})"
    return record
