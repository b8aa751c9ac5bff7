"""``seqrun trend [RUNS…]``: values drifting over a campaign's runs, and flaky runs.

    seqrun trend                                   # the campaign's runs -> runs/trend.html
    seqrun trend runs/ --sequence Op-safe --metric checkpoint_error_mm --csv trend.csv
    seqrun trend runs/2026112* --step 9 --limit 3  # (--limit needs --metric)

Reads only run folders (seqrun/report/trend.py, docs/campaigns.md "Trends"). Bad
arguments are one ``error:`` line and exit 2.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from seqrun.cli.app import app
from seqrun.cli.common import CampaignOption, user_errors

TREND_NAME = "trend.html"


@app.command("trend")
def trend_command(
    paths: Annotated[Optional[list[Path]], typer.Argument(
        metavar="RUNS_DIR|RUN_DIR", help="Folders of runs or run folders (default: the "
                                            "campaign's runs, as `seqrun runs` lists them).",
        show_default=False)] = None,
    sequence: Annotated[Optional[str], typer.Option(
        "--sequence", metavar="NAME", help="Only the runs of this sequence (its name or "
                                           "file stem).")] = None,
    step: Annotated[Optional[str], typer.Option(
        "--step", metavar="ID", help="Only this step (its number or label; 'run': the "
                                     "whole run's figures).")] = None,
    metric: Annotated[Optional[str], typer.Option(
        "--metric", metavar="METRIC", help="Only this metric: clearance_mm, duration_s, "
                                           "checkpoint_error_mm, peak_current_a, "
                                           "following_error_deg.")] = None,
    out: Annotated[Optional[Path], typer.Option(
        "--out", "-o", metavar="FILE.html", help="Write the page here (default: trend.html "
                                                 "in the (first) folder of runs).")] = None,
    csv_file: Annotated[Optional[Path], typer.Option(
        "--csv", metavar="FILE", help="Also write the values as CSV (one row per series "
                                      "and run).")] = None,
    limit: Annotated[Optional[float], typer.Option(
        "--limit", metavar="VALUE", help="The limit of --metric for every series (instead "
                                         "of the runs' own tolerances and guard lines).")
    ] = None,
    project_dir: CampaignOption = None,
) -> None:
    """The history of each value over a campaign's runs (oldest first): one self-contained
    HTML page with a plot per sequence, step and metric, the drift against the first run and
    against a limit, and the flaky runs (same inputs, different verdicts); a line per series
    here. A figure a run did not record is "not recorded", never filled in."""
    from seqrun.report.trend import summary_lines, trend, trend_csv
    from seqrun.report.trend_page import trend_html
    from seqrun.runfolder.logfile import write_whole

    with user_errors():
        if paths:
            where = [Path(p) for p in paths]
            named = ", ".join(map(str, where))
        else:
            from seqrun.service.arm_context import campaign_folders

            _, _, runs_dir = campaign_folders(project_dir=project_dir)
            where = [runs_dir] if runs_dir.is_dir() else []
            named = str(runs_dir)
        result = trend(where, sequence=sequence, step=step, metric=metric, limit=limit)
        for line in result.skipped:
            typer.echo(f"warning: {line}", err=True)
        if not result.runs:
            typer.echo(f"no runs in {named}")
            return
        for line in summary_lines(result):
            typer.echo(line)
        html = out if out is not None else _default_page(where, result.runs[0].folder)
        outputs = [(html, trend_html(result))]
        if csv_file is not None:
            outputs.append((csv_file, trend_csv(result)))
        for path, text in outputs:
            path.parent.mkdir(parents=True, exist_ok=True)
            error = write_whole(path, text)
            if error is not None:
                raise error
            typer.echo(f"wrote {path}")


def _default_page(where: list[Path], first_run: Path) -> Path:
    """trend.html in the first folder of runs given; given run folders only: beside them."""
    folders = [p for p in where if not (p / "report.json").is_file()
               and not (p / "arms.json").is_file()]
    return (folders[0] if folders else first_run.parent) / TREND_NAME
