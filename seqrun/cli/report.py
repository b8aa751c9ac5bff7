"""``seqrun report RUN_DIR``: (re)draw a run folder's report.html, or export its CSV.

    seqrun report runs/20261121-101500-Op-safe            # -> that folder's report.html
    seqrun report runs/20261121-101500-Op-safe --out r.html
    seqrun report runs/20261121-101500-Op-safe --csv exported/   # timeseries.csv, steps.csv
    seqrun report runs/20261121-101500-Op-safe --mcap     # run.mcap anew (docs/ros2.md);
                                                          # the recorded one -> run.mcap.orig
    seqrun report runs/20261127-101500-Two-arm --mcap     # several arms: their one run.mcap
    seqrun report --requirements runs/2026112*  --out matrix.html --csv matrix.csv
                                                          # requirement x run matrix

A folder that is not a run folder is one ``error:`` line and exit 2. A run of several arms
(docs/two-arms.md) draws each arm's report in its part (``RUN_DIR/A/report.html``; one
part for ``--out``/``--csv``); ``--mcap`` on the run's folder writes its one run.mcap of
every arm. ``--requirements`` takes any number of run folders and writes the requirement
matrix (seqrun/report/matrix.py, docs/campaigns.md "Requirements").
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Any, Optional

import typer

from seqrun.cli.app import app
from seqrun.cli.common import load_arm_file, user_errors


@app.command("report")
def report_command(
    run_dirs: Annotated[list[Path], typer.Argument(
        metavar="RUN_DIR…", help="A run folder (several with --requirements).")],
    out: Annotated[Optional[Path], typer.Option(
        "--out", "-o", metavar="FILE", help="Write the HTML here (default RUN_DIR/report.html)."
    )] = None,
    csv_dir: Annotated[Optional[Path], typer.Option(
        "--csv", metavar="DIR", help="Export the time series as CSV into DIR instead of the "
                                     "HTML (both with --out); with --requirements: the "
                                     "matrix as this CSV file.")] = None,
    requirements: Annotated[bool, typer.Option(
        "--requirements", help="Write the requirement matrix (requirement x run -> passed / "
                               "failed / not run) of the RUN_DIRs as HTML (--out, default "
                               "requirements.html beside the first run folder) and CSV "
                               "(--csv).")] = False,
    project: Annotated[Optional[Path], typer.Option(
        "--project", metavar="DIR", help="With --requirements: the campaign whose "
                                         "requirements.csv lists the requirements (default: "
                                         "the runs' campaign).")] = None,
    mcap: Annotated[bool, typer.Option(
        "--mcap", help="Write RUN_DIR/run.mcap (the run as a ROS 2 bag) anew from events.jsonl "
                       "instead of the HTML (both with --out); for runs of older versions or "
                       "one killed before its run.mcap was ended. The run.mcap the run "
                       "recorded is kept as run.mcap.orig.")] = False,
    arm_file: Annotated[Optional[Path], typer.Option(
        "--arm", metavar="FILE", help="Arm file, for run folders of versions that did not "
                                      "record the arm in events.jsonl.")] = None,
) -> None:
    """Draw the report of a run folder: report.html (self-contained, opens offline) with the
    run's identity, per-step tracking figures, checkpoints and plots; or CSV files."""
    from seqrun.report import export_csv, load_run, write_html

    with user_errors():
        if requirements:
            _matrix(run_dirs, out, csv_dir, project)
            return
        if len(run_dirs) != 1:
            from seqrun.errors import UserInputError

            raise UserInputError(f"one RUN_DIR (got {len(run_dirs)}); several only with "
                             "--requirements")
        run_dir = run_dirs[0]
        arm = load_arm_file(arm_file) if arm_file is not None else None
        if mcap:
            from seqrun.service.arms_mcap import is_arms_run, rebuild_arms_mcap
            from seqrun.service.mcap_log import rebuild_mcap

            with _keeping_the_recorded_bag(run_dir) as kept:
                path, counts = (rebuild_arms_mcap(run_dir) if is_arms_run(run_dir)
                                else rebuild_mcap(run_dir, arm))
            total = sum(counts.values())
            typer.echo(f"wrote {path} ({total} messages on {len(counts)} topics){kept}")
            if out is None and csv_dir is None:
                return
        parts = _parts(run_dir, out, csv_dir)
        if parts:  # a run of several arms: each arm's report, in its part
            for part in parts:
                data = load_run(part, arm=arm)
                _warn(part, data)
                typer.echo(f"wrote {write_html(part, None, data=data)}")
            return
        data = load_run(run_dir, arm=arm)
        _warn(run_dir, data)
        if csv_dir is not None:
            for path in export_csv(run_dir, csv_dir, data=data):
                typer.echo(f"wrote {path}")
        if csv_dir is None or out is not None:
            typer.echo(f"wrote {write_html(run_dir, out, data=data)}")


def _matrix(run_dirs: list[Path], out: Path | None, csv_file: Path | None,
            project: Path | None) -> None:
    """The requirement matrix of ``run_dirs``: HTML (and CSV)."""
    from seqrun.report.matrix import matrix_csv, matrix_html, requirement_matrix
    from seqrun.runfolder.logfile import write_whole

    matrix = requirement_matrix(run_dirs, project)
    for line in matrix.problems:
        typer.echo(f"warning: {line}", err=True)
    if matrix.source is None:
        typer.echo("warning: no requirements.csv found (give --project DIR): the matrix "
                   "lists only the requirements the runs verified", err=True)
    html = out if out is not None else Path(run_dirs[0]).parent / "requirements.html"
    for path, text in ((html, matrix_html(matrix)),
                       *(((csv_file, matrix_csv(matrix)),) if csv_file is not None else ())):
        path.parent.mkdir(parents=True, exist_ok=True)
        error = write_whole(path, text)
        if error is not None:
            raise error
        typer.echo(f"wrote {path}")


def _warn(run_dir: Path, data: Any) -> None:
    """One line each when the folder is cut short or its inputs/ were changed afterwards
    (report.html carries them as banners)."""
    for items, what in ((data.incomplete, "incomplete run folder"),
                        (data.inputs_changed, "inputs/ changed after the run")):
        if items:
            typer.echo(f"warning: {run_dir}: {what}: {'; '.join(items)}", err=True)


#: Where ``--mcap`` keeps the run.mcap the run recorded: a recorded bag is evidence.
RECORDED_MCAP = "run.mcap.orig"


@contextmanager
def _keeping_the_recorded_bag(run_dir: Path) -> Iterator[str]:
    """Before run.mcap is written anew: the run's own run.mcap moves to run.mcap.orig, and
    a killed run's run.mcap.partial/ (which the writer would clear) to
    run.mcap.partial.orig/; both are put back if writing fails. A run.mcap beside an
    existing run.mcap.orig was written by an earlier ``--mcap`` and is replaced; the
    recorded one stays. Yields the line's ending."""
    from seqrun.service.mcap_log import PARTIAL_NAME

    folder = Path(run_dir)
    moves: list[tuple[Path, Path]] = []   # (what the run recorded, where it is kept)
    for name, kept_name in (("run.mcap", RECORDED_MCAP),
                            (PARTIAL_NAME, PARTIAL_NAME + ".orig")):
        if (folder / name).exists() and not (folder / kept_name).exists():
            moves.append((folder / name, folder / kept_name))
    replaced = (folder / "run.mcap").is_file() and (folder / RECORDED_MCAP).exists()
    for source, kept in moves:
        source.replace(kept)
    try:
        yield ("".join(f"; the {source.name} the run recorded is kept as {kept}"
                       for source, kept in moves)
               + (f"; it replaces the run.mcap an earlier --mcap wrote (the recorded one "
                  f"stays in {folder / RECORDED_MCAP})" if replaced else ""))
    except BaseException:
        for source, kept in moves:
            if not source.exists():
                kept.replace(source)
        raise


def _parts(run_dir: Path, out: Path | None, csv_dir: Path | None) -> list[Path]:
    """A run of several arms: its arms' parts, each a run folder with a report of its own
    (none: a run of one arm). One file (``--out``) or one CSV export holds one arm: name
    its part."""
    from seqrun.errors import UserInputError
    from seqrun.service.arms_mcap import is_arms_run

    if not is_arms_run(run_dir) or (run_dir / "report.json").exists():
        return []
    parts = sorted(p for p in run_dir.iterdir() if (p / "report.json").is_file())
    if out is not None or csv_dir is not None:
        raise UserInputError(f"{run_dir}: a run of several arms: each arm's part is a run "
                             f"folder of its own ({', '.join(map(str, parts))}): name one "
                             f"for --{'out' if out is not None else 'csv'}")
    return parts
