"""Run records: what a run used, frozen in its run folder, and the list of past runs.

Every run folder gets ``inputs/`` (a copy of every file the run read: the sequence and its
includes, the pose files, the arm file, the campaign's ``seqrun.toml`` and
``requirements.csv``) and ``record.json``
(each input with its sha256, the seqrun version, the campaign's git commit and whether the
work tree was dirty, the bus and the zero reference). A run refused by validation leaves a
short folder too (``report.json`` with status ``refused`` and the errors), so a campaign's
run log is complete. ``seqrun runs`` lists the folders.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import os
import subprocess
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from seqrun.runfolder.logfile import write_whole
from seqrun.runfolder.names import EVENTS_NAMES, TRACE_NAMES
from seqrun.runfolder.requirements import campaign_requirements
from seqrun.shipped import shipped_dir

#: How long ``git rev-parse`` may take before the record says "unknown".
GIT_TIMEOUT_S = 5.0


def _copy_name(path: Path, root: Path | None) -> str:
    """Where an input goes under ``inputs/``: its path in the campaign, or ``_shipped/…``
    for a shipped file, else ``_other/<parent>/<name>``."""
    path = path.resolve()
    if root is not None and path.is_relative_to(root.resolve()):
        return path.relative_to(root.resolve()).as_posix()
    for kind in ("arms", "poses", "sequences"):
        folder = shipped_dir(kind).resolve()
        if path.is_relative_to(folder):
            return f"_shipped/{kind}/{path.relative_to(folder).as_posix()}"
    return f"_other/{path.parent.name or 'root'}/{path.name}"


def freeze_inputs(folder: Path, paths: Iterable[Path], root: Path | None = None) -> list[dict]:
    """Copy every file of ``paths`` into ``folder/inputs/`` and return one entry per file:
    ``{"path", "copy", "sha256", "bytes"}`` (duplicates dropped, order kept)."""
    sources = []
    for path in paths:
        path = Path(path)
        if path.is_file():
            sources.append((path, path.read_bytes()))
    return freeze_sources(folder, sources, root)


def freeze_sources(folder: Path, sources: Iterable[tuple[Path, bytes]],
                   root: Path | None = None) -> list[dict]:
    """Write the bytes of every ``(path, bytes)`` into ``folder/inputs/`` (where
    :func:`_copy_name` says) and return one entry per file: ``{"path", "copy", "sha256",
    "bytes"}`` (duplicates dropped, order kept). The bytes are those that were read and
    validated, never the file read again: a file edited since is recorded as it was used.
    An OSError (a full disk) is raised, with no partial copy left."""
    entries: list[dict] = []
    seen: set[Path] = set()
    for path, data in sources:
        path = Path(path).resolve()
        if path in seen:
            continue
        seen.add(path)
        name = _copy_name(path, root)
        target = Path(folder) / "inputs" / name
        target.parent.mkdir(parents=True, exist_ok=True)
        error = write_whole(target, data)
        if error is not None:
            raise error
        entries.append({"path": str(path), "copy": f"inputs/{name}",
                        "sha256": hashlib.sha256(data).hexdigest(), "bytes": len(data)})
    return entries


def input_sources(loaded: Any, arm: Any = None,
                  arm_path: Path | None = None) -> list[tuple[Path, bytes]]:
    """The files a loaded sequence was validated from, as the bytes read then: itself and
    its includes, the pose files its steps name, the arm file and the campaign config.
    (A file the loader did not keep, e.g. of a sequence built in code, is read now.)"""
    def read(path: Path) -> tuple[Path, bytes] | None:
        return (path, path.read_bytes()) if path.is_file() else None

    files = [Path(p) for p in loaded.files]
    kept = list(getattr(loaded, "sources", ()) or ())
    sources = list(zip(files, kept)) if len(kept) == len(files) else \
        [s for s in map(read, files) if s is not None]
    for pose in (getattr(loaded, "poses", None) or {}).values():
        sources.append((Path(pose.document.path), pose.document.source))
    sources.extend(_data_files(loaded, read))
    arm_file = Path(arm_path or loaded.arm_path)
    arm_bytes: bytes = getattr(arm, "source_bytes", None) or b""
    if arm_bytes:
        sources.append((arm_file, arm_bytes))
    elif (found := read(arm_file)) is not None:
        sources.append(found)
    project = getattr(loaded, "project", None)
    config = getattr(project, "config_path", None)
    if config is not None:
        source = getattr(project, "config_source", b"")
        if source:
            sources.append((Path(config), source))
        elif (found := read(Path(config))) is not None:
            sources.append(found)
        # The requirements the run's steps verify, as they read then (the matrix's list).
        listed = campaign_requirements(getattr(project, "root", None))
        if listed is not None and (found := read(listed)) is not None:
            sources.append(found)
    return sources


def _data_files(loaded: Any, read: Any) -> list[tuple[Path, bytes]]:
    """The data files the steps read (a ``move_trajectory``'s points), each once."""
    from seqrun.steps.registry import step_kind

    found: dict[Path, tuple[Path, bytes]] = {}
    for step in getattr(loaded, "steps", None) or ():
        try:
            names = step_kind(step.kind).data_files(step.params)
        except KeyError:
            continue
        for name in names:
            path = Path(step.location.file).parent / name
            if path not in found and (source := read(path)) is not None:
                found[path] = source
    return list(found.values())


def input_paths(loaded: Any, arm_path: Path | None = None) -> list[Path]:
    """The paths of :func:`input_sources`."""
    return [path for path, _ in input_sources(loaded, None, arm_path)]


def git_state(folder: Path) -> dict | None:
    """``{"commit", "dirty"}`` of the git work tree holding ``folder``; None when it is not
    in one (or git is missing); ``commit: None`` when git did not answer in time."""
    def git(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run(["git", "-C", str(folder), *args], capture_output=True,
                              text=True, timeout=GIT_TIMEOUT_S,
                              env={**os.environ, "GIT_OPTIONAL_LOCKS": "0"})

    try:
        head = git("rev-parse", "HEAD")
        if head.returncode != 0:
            return None
        status = git("status", "--porcelain", "--untracked-files=no")
    except FileNotFoundError:
        return None
    except subprocess.TimeoutExpired:
        return {"commit": None, "dirty": None, "note": f"git took over {GIT_TIMEOUT_S:g} s"}
    return {"commit": head.stdout.strip(), "dirty": bool(status.stdout.strip())}


def write_record(folder: Path, *, loaded: Any, arm_path: Path, bus: str,
                 zero: dict | None, inputs: list[dict] | None = None, arm: Any = None,
                 overrides: list[str] | None = None, arm_id: str | None = None) -> dict:
    """Freeze the inputs (unless given: the bytes validated, of ``loaded`` and ``arm``)
    and write ``record.json``; returns the record (``arm_id``: the arm of a campaign's
    ``[arms.ID]`` it ran on). Raises OSError (a full disk)."""
    from seqrun import __version__

    project = getattr(loaded, "project", None)
    root = getattr(project, "root", None)
    if inputs is None:
        inputs = freeze_sources(folder, input_sources(loaded, arm, arm_path), root)
    # the values of the sequence's parameters the run used (defaults and --param)
    params = dict(getattr(loaded, "param_values", None) or {})
    record = {
        "seqrun": __version__,
        "sequence": loaded.name,
        "file": str(loaded.file),
        "campaign": str(root) if getattr(project, "is_campaign", False) else None,
        "git": git_state(root) if root is not None else None,
        **({"arm_id": arm_id} if arm_id is not None else {}),
        "bus": bus,
        "zero": zero,
        "inputs": inputs,
        **({"overrides": list(overrides)} if overrides else {}),
        **({"params": params} if params else {}),
    }
    Path(folder).mkdir(parents=True, exist_ok=True)
    error = write_whole(Path(folder) / "record.json", json.dumps(record, indent=2) + "\n")
    if error is not None:
        raise error
    return record


def write_refusal(folder: Path, *, sequence: str, file: str, errors: list[dict],
                  loaded: Any = None, arm_path: Path | None = None, bus: str | None = None,
                  exit_code: int = 1, arm: Any = None, status: str = "refused",
                  message: str | None = None, arm_id: str | None = None) -> None:
    """The short record of a run that validation refused (or, with ``status`` and
    ``message``, that ended before it started): nothing was sent."""
    now = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="milliseconds")
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    report = {"sequence": sequence, "file": file, "start": now, "end": now,
              "status": status, "exit_code": exit_code,
              "message": message or f"refused by validation ({len(errors)} error"
                                    f"{'s' * (len(errors) != 1)}); nothing was sent",
              "duration_s": 0.0, "nothing_sent": True, "errors": errors}
    error = write_whole(folder / "report.json", json.dumps(report, indent=2) + "\n")
    if error is not None:
        raise error
    if loaded is not None:
        write_record(folder, loaded=loaded, arm_path=arm_path or loaded.arm_path,
                     bus=bus or "none (refused before the bus was opened)", zero=None,
                     arm=arm, arm_id=arm_id)


#: The result ``seqrun runs`` gives a folder whose files cannot be read as a run's.
CORRUPTED = "corrupted"


def list_runs(runs_dir: Path) -> list[dict]:
    """One entry per run folder under ``runs_dir`` (oldest first): when, sequence, result,
    duration, exit code, bus (and whether it was the simulator), folder, and which arm:
    ``arm`` (the ``[arms.ID]`` a run of one arm ran on, else None) and ``arms`` (the arms
    of a run of several, one part each; else None). A folder whose report.json is missing,
    unreadable or not a run's report is listed with the result ``corrupted`` and the
    ``problem``: it never hides the other runs."""
    runs: list[dict] = []
    if not Path(runs_dir).is_dir():
        return runs
    from seqrun.runfolder.names import is_suite_folder, runs_of_suite

    for folder in sorted(Path(runs_dir).iterdir()):
        if not folder.is_dir():
            continue
        # a suite's folder holds its runs: each listed as any other, named by its folder
        for run in runs_of_suite(folder) if is_suite_folder(folder) else [folder]:
            entry = _run_entry(run) or _arms_run_entry(run)
            if entry is not None:
                runs.append(entry)
    runs.sort(key=lambda r: (r["when"] or "", r["folder"]))
    return runs


def _read_json(path: Path) -> tuple[Any, str | None]:
    """``(data, None)``, or ``(None, what is wrong)``."""
    try:
        return json.loads(path.read_text(encoding="utf-8")), None
    except OSError as exc:
        return None, f"{path.name}: {exc.strerror or exc}"
    except UnicodeDecodeError:
        return None, f"{path.name}: not UTF-8 text"
    except ValueError as exc:
        return None, f"{path.name}: not JSON ({exc})"
    except RecursionError:
        return None, f"{path.name}: nested too deep"


def _run_entry(folder: Path) -> dict | None:
    """The listing of one folder; None when it holds no run at all."""
    report_file = folder / "report.json"
    looks_like_a_run = any((folder / name).exists() for name in (
        "report.json", "record.json", *EVENTS_NAMES, *TRACE_NAMES))
    if not looks_like_a_run:
        return None
    problem = None
    report: Any = {}
    if not report_file.is_file():
        problem = "no report.json"
    else:
        report, problem = _read_json(report_file)
        if problem is None and not isinstance(report, dict):
            problem, report = "report.json: not a run's report", {}
    report = report if isinstance(report, dict) else {}
    record, _ = _read_json(folder / "record.json") if (folder / "record.json").is_file() \
        else ({}, None)
    record = record if isinstance(record, dict) else {}

    def text(value: Any) -> str | None:
        return value if isinstance(value, str) else None

    exit_code = report.get("exit_code")
    exit_code = exit_code if isinstance(exit_code, int) and not isinstance(exit_code, bool) \
        else None
    result = text(report.get("status"))
    if problem is None and result is None:
        problem = "report.json: no status"
    bus = text(record.get("bus")) or text(report.get("bus"))
    return {"when": text(report.get("start")), "sequence": text(report.get("sequence")),
            "result": CORRUPTED if problem else result,
            "duration_s": _number(report.get("duration_s")), "exit_code": exit_code,
            "bus": bus, "simulator": _is_simulator(bus), "folder": str(folder),
            "arm": text(record.get("arm_id")), "arms": None,
            **_checked(folder),
            **({"problem": problem} if problem else {})}


def _checked(folder: Path) -> dict[str, list[str]]:
    """``incomplete`` (what of the folder is cut short or lacks its end) and
    ``inputs_changed`` (inputs/ files that are not as record.json recorded them): empty
    lists for a whole run whose inputs are as it used them."""
    from seqrun.runfolder.integrity import changed_inputs, incomplete

    return {"incomplete": incomplete(folder), "inputs_changed": changed_inputs(folder)}


def runs_of_arm(runs: list[dict], arm_id: str) -> list[dict]:
    """The entries of :func:`list_runs` that moved the campaign's arm ``arm_id``: its runs
    of one arm, the runs of several arms it was part of, and the runs that do not say
    which arm they ran on (recorded before runs named their arm: they are not hidden)."""
    return [r for r in runs if (r.get("arms") is None and r.get("arm") in (None, arm_id))
            or arm_id in (r.get("arms") or ())]


def _arms_run_entry(folder: Path) -> dict | None:
    """The listing of a run of several arms (``arms.json``, one part folder per arm, named
    by its arm); None when the folder holds none (a folder that only groups runs). While it
    runs (no arms.json yet) its parts say so."""
    parts = {p.name: e for p in sorted(folder.iterdir())
             if p.is_dir() and (e := _run_entry(p)) is not None and e["arm"] == p.name}
    summary_file = folder / "arms.json"
    if not parts and not summary_file.is_file():
        return None
    summary, problem = _read_json(summary_file) if summary_file.is_file() else (
        None, "no arms.json")
    summary = summary if isinstance(summary, dict) else {}
    if problem is None and not isinstance(summary.get("arms"), dict):
        problem = "arms.json: no arms"
    given = summary.get("arms")
    arms: dict = given if isinstance(given, dict) else {}
    ids = [str(a) for a in arms] or list(parts)
    statuses = [s.get("status") for s in arms.values() if isinstance(s, dict)]
    running = any(e["result"] == "running" for e in parts.values())
    result: str | None
    if problem and running:
        problem, result = None, "running"
    elif problem:
        result = CORRUPTED
    else:
        result = next((s for s in statuses if s != "passed"), "passed")
    exit_code = summary.get("exit_code")
    exit_code = exit_code if isinstance(exit_code, int) and not isinstance(exit_code, bool) \
        else None
    time_base = summary.get("time_base")
    base: dict = time_base if isinstance(time_base, dict) else {}
    starts = [e["when"] for e in parts.values() if e["when"]]
    durations = [e["duration_s"] for e in parts.values() if e["duration_s"] is not None]
    buses = [e["simulator"] for e in parts.values()]
    sequence = summary.get("sequence")
    return {"when": base.get("utc") if isinstance(base.get("utc"), str)
            else min(starts, default=None),
            "sequence": sequence if isinstance(sequence, str) else None,
            "result": result, "duration_s": max(durations, default=None),
            "exit_code": exit_code,
            "bus": "; ".join(f"{a}: {e['bus']}" for a, e in parts.items() if e["bus"]) or None,
            "simulator": (None if not buses or None in buses else all(buses)),
            "folder": str(folder), "arm": None, "arms": ids,
            **{key: [f"{a}: {x}" for a, e in parts.items() for x in e[key]] + found
               for key, found in _checked(folder).items()},   # each arm's part, the run's
            **({"problem": problem} if problem else {})}


def _number(value: Any) -> float | None:
    ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    return float(value) if ok and value == value else None


def _is_simulator(bus: str | None) -> bool | None:
    """Whether a recorded bus description is a simulator's (None: no bus was opened)."""
    if bus is None or bus.startswith("none"):
        return None
    return bus.startswith("SIMULATOR")
