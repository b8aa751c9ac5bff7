"""The report's plots, drawn with matplotlib (Agg, no display) and kept as inline SVG.

Every plot against time shows the step boundaries (grey, numbered at the top) and the
fault, if any (red, at its time). Long runs come decimated to an envelope of
``MAX_POINTS`` points per line (:mod:`seqrun.report.summary`), which keeps the page a few
MB however long the run; the extremes the captions state are exact. Text is drawn as
paths: the SVG needs no font.
"""

from __future__ import annotations

import gc
import io
import re
from dataclasses import dataclass
from collections.abc import Callable, Iterator
from functools import partial

import numpy as np

from seqrun.report.data import MAX_POINTS, RunData
from seqrun.report.figures import loop_periods, period_stats, step_spans

__all__ = ["MAX_POINTS", "Plot", "iter_plots", "new_figure", "render_plots", "to_svg"]
#: matplotlib drops path vertices closer than this (pixels) to the line: quantised noise
#: (following errors in 0.001° steps) costs no bytes it could show.
SIMPLIFY_THRESHOLD = 0.3

PLANNED = dict(color="#7f7f7f", linestyle="--", linewidth=1.1, label="planned")
MEASURED = dict(color="#1f77b4", linestyle="-", linewidth=1.0, label="measured")
LIMIT = dict(color="#d62728", linestyle="--", linewidth=0.8, alpha=0.8)
MOVE_LIMIT = dict(color="#ff7f0e", linestyle=":", linewidth=1.2)
STEP_LINE = dict(color="#999999", linewidth=0.5, alpha=0.7)
FAULT_LINE = dict(color="#d62728", linewidth=1.8)


@dataclass
class Plot:
    id: str
    title: str
    caption: str
    svg: str


def render_plots(data: RunData) -> list[Plot]:
    """Every plot of the report (none without samples or without the arm description)."""
    return list(iter_plots(data))


def iter_plots(data: RunData) -> Iterator[Plot]:
    """The plots one at a time, each drawn when it is asked for (a page written as it is
    drawn holds one plot's SVG at a time)."""
    import matplotlib

    matplotlib.use("Agg")
    if data.arm is None or data.reading_count == 0 or data.dof != data.arm.dof:
        return
    drawings: list[Callable[[], Plot]] = [partial(_joint_plot, data, i)
                                          for i in range(data.arm.dof)]
    if data.arm.workspace.guards:
        drawings.append(lambda: _guard_plot(data))
    if not data.virtual_time:
        periods, counts = loop_periods(data)
        if periods.size:
            drawings.append(lambda: _period_plot(data, periods, counts))
    for draw in drawings:
        plot = draw()
        # A drawn figure is a web of reference cycles (tens of MB for a long run's steps):
        # collected before the next one is drawn, not whenever the collector comes by.
        gc.collect()
        yield plot


# ---------------------------------------------------------------------------- helpers
def new_figure(height: float, rows: int = 1):
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, height))
    # Fixed margins (inches) instead of a layout engine: the engine's extra draw pass
    # doubled the time a report takes.
    fig.subplots_adjust(left=0.8 / 10, right=1 - 0.15 / 10, top=1 - 0.45 / height,
                        bottom=0.5 / height, hspace=0.18 if rows > 1 else 0.0)
    axes = fig.subplots(rows, 1, sharex=True, squeeze=False)[:, 0]
    for ax in axes:
        ax.grid(True, linewidth=0.3, alpha=0.5)
        ax.tick_params(labelsize=8)
    return fig, axes


def to_svg(fig, name: str) -> str:
    import matplotlib

    buf = io.StringIO()
    # A salt per plot: ids inside each SVG are reproducible and unique on the page.
    with matplotlib.rc_context({"svg.hashsalt": f"seqrun-{name}", "svg.fonttype": "path",
                                "path.simplify_threshold": SIMPLIFY_THRESHOLD}):
        fig.savefig(buf, format="svg", metadata={"Date": None, "Creator": None})
    svg = buf.getvalue()
    svg = svg[svg.index("<svg"):]                       # drop the XML prolog and doctype
    svg = re.sub(r"<metadata>.*?</metadata>\s*", "", svg, count=1, flags=re.S)
    # Path data to 0.1 pt (the figure is 720 pt wide): halves the page, nothing visible.
    svg = re.sub(r' d="([^"]*)"',
                 lambda m: ' d="' + " ".join(_NUMBER.sub(_round, m.group(1)).split()) + '"', svg)
    svg = re.sub(r">\s+<", "><", svg)        # indentation (no text nodes: text is paths)
    # Scale with the page: keep the viewBox, let CSS set the size.
    return re.sub(r'^<svg([^>]*?) width="[^"]*" height="[^"]*"', r'<svg\1', svg, count=1)


_NUMBER = re.compile(r"-?\d+\.\d+")


def _round(m: re.Match) -> str:
    text = f"{float(m.group(0)):.1f}"
    text = text[:-2] if text.endswith(".0") else text
    return "0" if text == "-0" else text


def _segments(ax, x0, y0, x1, y1, *, transform=None, **style) -> None:
    """Straight segments (x0, y0)-(x1, y1) drawn as one line broken by NaN: one SVG path
    however many a run of thousands of steps has (a dash pattern restarts per segment)."""
    gap = np.full(len(x0), np.nan)
    x = np.column_stack([x0, x1, gap]).ravel()
    y = np.column_stack([y0, y1, gap]).ravel()
    ax.plot(x, y, transform=transform if transform is not None else ax.transData, **style)


def _line(ax, data: RunData, name: str, style) -> None:
    t, y = data.overview.line(name)
    ax.plot(t, y, **style)


def _time_axes(data: RunData, axes, name: str, *, label_steps: bool = True) -> None:
    """Step boundaries, the fault and the x range on every axes of a time plot."""
    spans = step_spans(data)
    end = max([s[2] or s[1] for s in spans] + [float(data.overview.t_last or 0.0)])
    fault_t = (data.fault or {}).get("t")
    starts = [start for _, start, _ in spans]
    for k, ax in enumerate(axes):
        # One line for all boundaries: a line object per step and axes made long runs
        # (hundreds of steps) slow to draw; a collection writes an SVG element per step.
        _segments(ax, starts, [0.0] * len(starts), starts, [1.0] * len(starts),
                  transform=ax.get_xaxis_transform(), **STEP_LINE)
        if fault_t is not None:
            # gid: the SVG group gets an id, so the marker can be found in the page.
            ax.axvline(fault_t, **FAULT_LINE, label="fault", gid=f"{name}-fault-{k}")
        ax.set_xlim(0, end * 1.01 if end > 0 else 1)
    axes[-1].set_xlabel("time since run start (s)", fontsize=8)
    if label_steps and spans:
        _label_steps(axes[0], spans, end)
    if fault_t is not None:
        cause = (data.fault or {}).get("cause") or "fault"
        right = fault_t > 0.6 * end          # label on the side with room
        axes[0].annotate(f"fault: {cause}", xy=(fault_t, 1.0), xycoords=("data", "axes fraction"),
                         xytext=(-4 if right else 4, 2), textcoords="offset points",
                         ha="right" if right else "left", va="bottom", color="#d62728",
                         fontsize=8, fontweight="bold")


def _label_steps(ax, spans, end: float) -> None:
    """Step numbers above the top axes; steps closer than 1.5 % of the run share a label,
    and labels keep 4 % of the width apart (long runs: some lines go unnumbered)."""
    groups: list[list] = []
    for number, start, _ in spans:
        if groups and start - groups[-1][0][1] < 0.015 * max(end, 1e-9):
            groups[-1].append((number, start))
        else:
            groups.append([(number, start)])
    last_x = -float("inf")
    for group in groups:
        if group[0][1] - last_x < 0.04 * max(end, 1e-9):
            continue                     # no room: the line stays, the number goes
        last_x = group[0][1]
        first, last = group[0][0], group[-1][0]
        text = str(first) if first == last else f"{first}-{last}"
        ax.annotate(text, xy=(group[0][1], 1.0), xycoords=("data", "axes fraction"),
                    xytext=(1, 2), textcoords="offset points", fontsize=7, color="#555555")


# ---------------------------------------------------------------------------- plots
def _joint_plot(data: RunData, i: int) -> Plot:
    arm = data.arm
    assert arm is not None  # (plots() draws none without the arm)
    joint = arm.joints[i]
    fig, (pos, vel, err) = new_figure(6.4, rows=3)
    _line(pos, data, f"planned.{i}", PLANNED)
    _line(pos, data, f"measured.{i}", MEASURED)
    lo, hi = joint.limits_deg
    pos.axhline(lo, **LIMIT, label=f"limits {lo:g}/{hi:g}°")
    pos.axhline(hi, **LIMIT)
    pos.set_ylabel("position (°)", fontsize=8)

    _line(vel, data, f"planned_vel.{i}", PLANNED)
    _line(vel, data, f"measured_vel.{i}", MEASURED)
    vmax = joint.max_velocity_deg_s
    vel.axhline(vmax, **LIMIT, label=f"arm limit ±{vmax:g}°/s")
    vel.axhline(-vmax, **LIMIT)
    limits, begins, ends = [], [], []
    for step in data.steps:
        limit = (step.move or {}).get("velocity_limit_deg_s")
        if not limit or step.started_t is None:
            continue
        end = step.finished_t if step.finished_t is not None else float(
            data.overview.t_last or step.started_t)
        limits += [limit[i], -limit[i]]
        begins += [step.started_t] * 2
        ends += [end] * 2
    if limits:
        _segments(vel, begins, limits, ends, limits, **MOVE_LIMIT,
                  label="planner limit of the move")
    vel.set_ylabel("velocity (°/s)", fontsize=8)

    _line(err, data, f"error.{i}", dict(color="#2ca02c", linewidth=0.9,
                                        label="planned − measured"))
    bound = arm.control.max_following_error_deg
    worst_all = data.overview.worst_error_deg
    worst = float(worst_all[i]) if worst_all is not None and np.isfinite(worst_all[i]) else 0.0
    if worst > 0.25 * bound:
        err.axhline(bound, **LIMIT, label=f"bound ±{bound:g}°")
        err.axhline(-bound, **LIMIT)
    err.set_ylabel("following error (°)", fontsize=8)

    _time_axes(data, (pos, vel, err), f"plot-{joint.name}")
    for ax in (pos, vel, err):
        ax.legend(fontsize=7, loc="upper right", framealpha=0.7)
    locked = f", locked at {joint.locked:g}°" if joint.locked is not None else ""
    title = f"{joint.name} (module {joint.module}{locked})"
    fig.suptitle(title, fontsize=10)
    caption = (f"{joint.name}: position, velocity and following error, planned (dashed) vs "
               f"measured; worst |planned − measured| {worst:.3f}° (bound {bound:g}°). "
               "Measured velocity: windowed estimate over "
               f"{data.velocity_window_s * 1e3:.0f} ms.")
    return Plot(f"plot-{joint.name}", title, caption, to_svg(fig, joint.name))


def _guard_plot(data: RunData) -> Plot:
    arm = data.arm
    assert arm is not None  # (plots() draws none without the arm)
    fig, (ax,) = new_figure(3.6)
    guard_colours = ["#d62728", "#8c564b", "#e377c2", "#7f7f7f"]
    point_colours = ["#1f77b4", "#2ca02c", "#9467bd", "#17becf", "#bcbd22", "#ff7f0e"]
    lines, k = [], 0
    for g, guard in enumerate(arm.workspace.guards):
        ax.axhline(guard.min_z_mm, color=guard_colours[g % len(guard_colours)],
                   linestyle="-.", linewidth=1.2,
                   label=f"guard '{guard.name}': {guard.min_z_mm:g} mm")
        for point in guard.points:
            _line(ax, data, f"guard.{guard.name}.{point}",
                  dict(color=point_colours[k % len(point_colours)], linewidth=1.1,
                       label=f"{point.replace('_', ' ')} ({guard.name})"))
            k += 1
            lowest = data.overview.lowest_mm.get((guard.name, point))
            if lowest is not None and np.isfinite(lowest):
                lines.append(f"{point} lowest {lowest:.1f} mm")
    ax.set_ylabel("height above the base plane (mm)", fontsize=8)
    _time_axes(data, [ax], "plot-guards")
    ax.legend(fontsize=7, loc="upper right", framealpha=0.7)
    fig.suptitle("Guard points", fontsize=10)
    caption = ("Height of every guarded point (forward kinematics of the measured joints) "
               "against each guard's line; " + "; ".join(lines) + ".")
    return Plot("plot-guards", "Guard points", caption, to_svg(fig, "guards"))


def _period_plot(data: RunData, periods_ms: np.ndarray, counts: np.ndarray) -> Plot:
    fig, (ax,) = new_figure(3.0)
    ax.hist(periods_ms, bins=80, weights=counts, color="#1f77b4")
    ax.set_yscale("log")
    if data.cycle_s:
        ax.axvline(data.cycle_s * 1e3, **LIMIT, label=f"cycle {data.cycle_s * 1e3:g} ms")
        ax.legend(fontsize=7, loc="upper right")
    stats = period_stats(data)
    ax.set_xlabel("control loop period (ms)", fontsize=8)
    ax.set_ylabel("cycles", fontsize=8)
    fig.suptitle("Control loop period", fontsize=10)
    caption = (f"Time between consecutive cycles of a move (their readings in "
               f"events.jsonl): {stats['count']} periods, "
               f"median {stats['median_ms']:.2f} ms, p99 {stats['p99_ms']:.2f} ms, "
               f"max {stats['max_ms']:.2f} ms.")
    if data.fault:
        caption += " (Not a plot against time: the fault is marked on the others.)"
    return Plot("plot-loop-period", "Control loop period", caption, to_svg(fig, "period"))
