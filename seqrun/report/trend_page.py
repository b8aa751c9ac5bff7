"""The trend page: one self-contained HTML page (inline CSS and SVG, no script, no link).

At the top the runs (numbered in the order they started) and the flaky groups; then, per
sequence, a table of every series (first, last, drift, worst, limit) and, per series that
any run recorded, its history as a plot (drawn with the report's matplotlib helpers) and
a table of its points: value, drift against the first run, margin to the limit.
"""

from __future__ import annotations

import datetime as _dt
import gc
from html import escape

from seqrun.report.trend import NOT_RECORDED, Series, Trend, short

_STATUS_COLOUR = {"passed": "#2ca02c"}
_OTHER_COLOUR = "#d62728"


def _fmt(value: float | None, sign: bool = False) -> str:
    if value is None:
        return "-"
    return f"{value:+g}" if sign else f"{value:g}"


def _anchor(s: Series) -> str:
    return "series-" + "-".join("".join(c if c.isalnum() else "_" for c in part)
                                for part in (s.sequence, s.step, s.metric, s.item) if part)


def _plot(s: Series, index: dict[int, int]) -> str:
    """The series' history as SVG: recorded values (a dot per run, red when the step or
    run did not pass), the first run's value, the limit."""
    import matplotlib

    matplotlib.use("Agg")
    from seqrun.report.plots import LIMIT, new_figure, to_svg

    fig, (ax,) = new_figure(2.6)
    xs = [index[id(p.run)] for p in s.points]
    recorded = [(x, p) for x, p in zip(xs, s.points) if p.number is not None]
    ax.plot([x for x, _ in recorded], [p.number for _, p in recorded], color="#1f77b4",
            linewidth=1.0, label=s.metric)
    for colour, label, want in (("#2ca02c", "passed", True), (_OTHER_COLOUR, "not passed",
                                                                False)):
        chosen = [(x, p) for x, p in recorded if (p.status == "passed") == want]
        if chosen:
            ax.plot([x for x, _ in chosen], [p.number for _, p in chosen], linestyle="none",
                    marker="o", markersize=5, color=colour, label=label)
    if s.first is not None:
        ax.axhline(s.first, color="#7f7f7f", linestyle=":", linewidth=1.0,
                   label=f"first run {s.first:g}")
    limits = [(x, p.limit) for x, p in zip(xs, s.points) if p.limit is not None]
    if limits:
        ax.step([x for x, _ in limits], [v for _, v in limits], where="mid", **LIMIT,
                label=f"limit {limits[-1][1]:g}")
    missing = [x for x, p in zip(xs, s.points) if p.number is None]
    if missing:
        ax.plot(missing, [0.02] * len(missing), transform=ax.get_xaxis_transform(),
                linestyle="none", marker="x", color="#999999", label="not recorded / not run")
    # A label per run up to 25 runs; beyond, every k-th (the runs table names them all).
    ticks = sorted(set(xs))[::max(1, -(-len(set(xs)) // 25))]
    ax.set_xticks(ticks)
    ax.set_xticklabels([f"#{x}" for x in ticks])
    ax.set_xlim(min(xs) - 0.5, max(xs) + 0.5)
    ax.set_xlabel("run (in the order they started)", fontsize=8)
    ax.set_ylabel(s.metric, fontsize=8)
    ax.legend(fontsize=7, loc="best", framealpha=0.7)
    svg = to_svg(fig, _anchor(s))
    gc.collect()
    return svg


def _value(value: float | str) -> str:
    return escape(value) if isinstance(value, str) else f"{value:g}"


def _series_section(s: Series, index: dict[int, int]) -> str:
    anchor = _anchor(s)
    if not s.recorded:
        return (f'<section class="series" id="{anchor}"><h3>{escape(s.title)}</h3>'
                f'<p class="note">{NOT_RECORDED} in any of the {len(s.points)} run(s).</p>'
                "</section>")
    rows = []
    for p in s.points:
        margin = s.margin_of(p)
        beyond = margin is not None and margin < 0
        rows.append(
            f'<tr class="{"beyond" if beyond else ""}" data-run="{escape(p.run.name)}">'
            f'<td class="num">#{index[id(p.run)]}</td><td class="mono">{escape(p.run.name)}'
            f'</td><td>{escape(p.status or "-")}</td>'
            f'<td class="num value">{_value(p.value)}</td>'
            f'<td class="num">{_fmt(s.drift_of(p), sign=True)}</td>'
            f'<td class="num">{_fmt(p.limit)}</td><td class="num">{_fmt(margin, sign=True)}'
            "</td></tr>")
    limit = s.limit
    source = (f" Limit: {escape(limit.limit_source)}." if limit is not None else
              " No limit known (give one with --limit).")
    return (f'<section class="series" id="{anchor}"><h3>{escape(s.title)}</h3>'
            f'<figure class="plot">{_plot(s, index)}<figcaption>{escape(s.title)}: the value '
            "per run (dots: green when the step passed), the first run's value (dotted) and "
            f"the limit (red dashed).{source}</figcaption></figure>"
            '<table class="figs"><tr><th>#</th><th>run</th><th>verdict</th><th>value</th>'
            "<th>drift vs first</th><th>limit</th><th>margin</th></tr>"
            f"{''.join(rows)}</table></section>")


def _overview_row(s: Series) -> str:
    worst = s.worst
    limit = s.limit
    margin = s.margin_of(worst) if worst is not None else None
    return (f'<tr><td><a href="#{_anchor(s)}">{escape(s.title)}</a></td>'
            f'<td class="num">{_fmt(s.first)}</td><td class="num">{_fmt(s.last)}</td>'
            f'<td class="num">{_fmt(s.drift, sign=True)}</td>'
            f'<td class="num">{_fmt(worst.number if worst else None)}</td>'
            f'<td class="num">{_fmt(limit.limit if limit else None)}</td>'
            f'<td class="num{" beyond" if margin is not None and margin < 0 else ""}">'
            f'{_fmt(margin, sign=True)}</td><td class="num">{len(s.recorded)}/{len(s.points)}'
            "</td></tr>")


def trend_html(t: Trend) -> str:
    """The page (see the module's docstring)."""
    from seqrun import __version__
    from seqrun.report.html import CSS

    index = {id(run): k + 1 for k, run in enumerate(t.runs)}
    runs = "".join(
        f'<tr id="run-{k}"><td class="num">#{k}</td><td class="mono">{escape(r.name)}</td>'
        f"<td>{escape(r.sequence)}</td><td>{escape((r.start or NOT_RECORDED)[:19])}</td>"
        f'<td><span class="badge {"passed" if r.status == "passed" else "failed"}">'
        f"{escape(r.status)}</span></td><td class=\"mono\">{escape(short(r.inputs))}</td>"
        f"<td class=\"mono\">{escape(' '.join(r.faults))}</td></tr>"
        for k, r in ((index[id(r)], r) for r in t.runs))
    flaky = "".join(
        f'<tr class="flaky"><td>{escape(g.sequence)}</td><td class="mono">{escape(short(g.inputs))}'
        f"</td><td>{escape(', '.join(f'{n} {v}' for v, n in g.verdicts.items()))}</td><td>"
        + ", ".join(f"#{index[id(r)]} {escape(r.name)} ({escape(r.status)}"
                    + (f", --sim-fault {escape(' '.join(r.faults))}" if r.faults else "") + ")"
                    for r in g.runs) + "</td></tr>"
        for g in t.flaky)
    flaky_part = (
        '<table id="flaky"><tr><th>sequence</th><th>inputs (sha256)</th><th>verdicts</th>'
        f"<th>runs</th></tr>{flaky}</table>" if t.flaky else
        '<p id="flaky" class="note">No flaky runs: every set of runs with the same inputs '
        "has one verdict.</p>")
    sections = []
    for sequence in dict.fromkeys(s.sequence for s in t.series):
        of_it = [s for s in t.series if s.sequence == sequence]
        sections.append(
            f"<h2>{escape(sequence)}</h2>"
            '<table class="figs overview"><tr><th>series</th><th>first</th><th>last</th>'
            "<th>drift</th><th>worst</th><th>limit</th><th>worst's margin</th>"
            f"<th>recorded</th></tr>{''.join(_overview_row(s) for s in of_it)}</table>"
            + "".join(_series_section(s, index) for s in of_it))
    skipped = "".join(f'<li class="mono">{escape(line)}</li>' for line in t.skipped)
    now = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    css = CSS + """
tr.beyond td,td.beyond{background:#fdecea;color:#a31515;font-weight:600}
tr.flaky td{background:#fff4e5}section.series{margin:1.2em 0}
h3{font-size:1em;margin:1em 0 .3em}
"""
    return "\n".join((
        "<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
        "<title>Trends</title>", f"<style>{css}</style></head><body>",
        "<h1>Trends</h1>",
        f"<p>{len(t.series)} series over {len(t.runs)} run(s), in the order they started. "
        "Drift is a value minus the first run's; the margin is how far a value is inside its "
        "limit (negative: beyond it). A figure a run did not record is "
        f"<em>{NOT_RECORDED}</em>; a step it never reached, <em>not run</em>.</p>",
        f"<ul>{skipped}</ul>" if skipped else "",
        '<h2>Runs</h2><table id="runs"><tr><th>#</th><th>run</th><th>sequence</th>'
        "<th>start</th><th>result</th><th>inputs (sha256)</th><th>--sim-fault</th></tr>"
        f"{runs}</table>",
        "<h2>Flaky</h2><p class=\"note\">Runs of a sequence with the same inputs (the "
        "sha256 of every input file record.json keeps) and different verdicts.</p>",
        flaky_part, *sections,
        f'<p class="note">Written by seqrun {escape(__version__)} at {escape(now)}.</p>',
        "</body></html>")) + "\n"
