"""``seqrun runs [--json] [--arm-id ID]``: the past runs of a campaign (or of ``runs/`` here)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Optional

import typer

from seqrun.cli.app import app
from seqrun.cli.common import CampaignOption, OneArmOption, fail, user_errors
from seqrun.service.records import list_runs, runs_of_arm


def _local(when: str | None) -> str:
    """An ISO time as local 'YYYY-MM-DD HH:MM:SS'."""
    from datetime import datetime

    try:
        return datetime.fromisoformat(str(when)).astimezone().strftime("%Y-%m-%d %H:%M:%S")
    except ValueError:
        return str(when or "-")[:19]


@app.command("runs")
def runs_command(
    as_json: Annotated[bool, typer.Option("--json", help="Machine-readable output.")] = False,
    project_dir: CampaignOption = None,
    runs_dir: Annotated[Optional[Path], typer.Option(
        "--dir", metavar="DIR", help="Run folders to list (default: the campaign's, else "
                                     "runs/).")] = None,
    arm_id: OneArmOption = None,
) -> None:
    """List past runs: when, sequence, result, duration, exit code (oldest first). In a
    campaign with several arms: every run of each arm, and the runs of several arms
    (--arm-id ID: those that moved that arm). A run whose folder is cut short (a full
    disk: events, trace or run.mcap stop mid-run) is marked INCOMPLETE, one whose inputs/
    were changed after it ran INPUTS CHANGED (--json: "incomplete", "inputs_changed")."""
    from seqrun.service.arm_context import campaign_arm_ids, campaign_folders

    with user_errors():
        project, _, runs_in = campaign_folders(project_dir=project_dir)
        runs_dir = runs_in if runs_dir is None else runs_dir
        ids = campaign_arm_ids(project)
        if arm_id is not None and arm_id not in ids:
            fail(f"--arm-id {arm_id}: {project.describe()} "
                 + (f"has arms {', '.join(ids)}" if ids else "names no arms ([arms.ID])"))
        runs = list_runs(runs_dir)
    if arm_id is not None:
        runs = runs_of_arm(runs, arm_id)
    if as_json:
        typer.echo(json.dumps(runs, indent=2))
        return
    if not runs:
        typer.echo(f"no runs in {runs_dir}" + (f" of arm {arm_id}" if arm_id else ""))
        return
    arms_shown = any(r.get("arm") or r.get("arms") for r in runs)
    typer.echo(f"{'when':19s} {'sequence':24s} {'result':10s} {'duration':>9s} {'exit':>4s} "
               f"{'bus':4s}" + (" arm" if arms_shown else ""))
    for run in runs:
        duration = run["duration_s"]
        bus = {True: "sim", False: "REAL", None: "-"}[run["simulator"]]
        line = (f"{_local(run['when']):19s} {str(run['sequence'] or '-')[:24]:24s} "
                f"{str(run['result'] or '-')[:10]:10s} "
                f"{'-' if duration is None else f'{duration:.2f} s':>9s} "
                f"{'-' if run['exit_code'] is None else run['exit_code']:>4} {bus:4s}")
        if arms_shown:
            line += " " + (",".join(run.get("arms") or ()) or run.get("arm") or "-")
        if run.get("problem"):  # what is wrong, and where
            line += f" {run['problem']} ({Path(run['folder']).name})"
        line += "".join(f" {mark}: {run[key][0]}" + (f" (+{len(run[key]) - 1} more)"
                                                     if len(run[key]) > 1 else "")
                        for key, mark in _MARKS if run.get(key))
        typer.echo(line.rstrip())
    corrupted = sum(1 for run in runs if run.get("problem"))
    marked = [f"{n} {mark.lower()}" for key, mark in _MARKS
              if (n := sum(1 for run in runs if run.get(key)))]
    typer.echo(f"{len(runs)} run{'s' * (len(runs) != 1)} in {runs_dir}"
               + (f" of arm {arm_id}" if arm_id else "")
               + (f", {corrupted} corrupted" if corrupted else "")
               + "".join(f", {m}" for m in marked)
               + (" (seqrun report RUN_DIR says what)" if marked else ""))


#: The marks of a run that is not what its result alone says (service.records' fields).
_MARKS = (("incomplete", "INCOMPLETE"), ("inputs_changed", "INPUTS CHANGED"))
