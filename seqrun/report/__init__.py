"""Reports of a run folder: report.html (plots as inline SVG) and CSV export.

    data = load_run(folder)              # seqrun/report/data.py: the one loader
    write_html(folder)                   # folder/report.html
    export_csv(data, out_dir)            # timeseries.csv, steps.csv

Only this package imports matplotlib, and only when a report is drawn; the executor emits
the data (events.jsonl, report.json) and knows nothing of reports.
"""

from __future__ import annotations

from pathlib import Path

from seqrun.arm.description import ArmDescription
from seqrun.report.data import RunData, load_run
from seqrun.runfolder.logfile import write_streamed

HTML_NAME = "report.html"


def write_html(folder: str | Path, out: str | Path | None = None, *,
               arm: ArmDescription | None = None, data: RunData | None = None) -> Path:
    """Draw the report of run folder ``folder`` into ``out`` (default folder/report.html)."""
    from seqrun.report.html import html_parts
    from seqrun.report.plots import iter_plots

    data = data if data is not None else load_run(folder, arm=arm)
    target = Path(out) if out is not None else Path(folder) / HTML_NAME
    plots = iter_plots(data)   # drawn one at a time as the page is written
    # Through the run folder's writer: a full disk leaves no report.html.tmp behind.
    error = write_streamed(target, html_parts(data, plots))
    if error is not None:
        raise error
    return target


def export_csv(folder: str | Path, out_dir: str | Path, *, arm: ArmDescription | None = None,
               data: RunData | None = None) -> list[Path]:
    """Write the time series of run folder ``folder`` as CSV files into ``out_dir``."""
    from seqrun.report.csvout import export_csv as _export

    return _export(data if data is not None else load_run(folder, arm=arm), out_dir)


__all__ = ["HTML_NAME", "RunData", "export_csv", "load_run", "write_html"]
