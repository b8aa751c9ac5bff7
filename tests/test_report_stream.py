"""The report of a long run: events.jsonl streamed once, in bounded memory, decimated lines
that keep their envelope, and exact extremes (issue 29 item 2).

The runs here are synthetic event logs (longer than a plot's ``MAX_POINTS``, so decimation
is in play); every figure is held against a recomputation from all the readings with plain
numpy and the kinematics.
"""

from __future__ import annotations

import gc
import json
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from projecttree import shipped_arm
from seqrun.arm import kinematics
from seqrun.arm.tracking import peak_abs, windowed_velocity
from seqrun.report import load_run, write_html
from seqrun.report import data as data_module
from seqrun.report import readings as readings_module
from seqrun.report.data import MAX_POINTS, from_records
from seqrun.report.envelope import BASE_WIDTH_S, Envelope
from seqrun.report.figures import recompute_move_figures
from seqrun.report.readings import Series
from tiers import examples

ARM = shipped_arm()
CYCLE_S = 0.01
WINDOW_S = 0.1


def synthetic_run(moves: int, cycles: int, *, seed: int = 0) -> list[dict]:
    """A run of ``moves`` moves of ``cycles`` streamed cycles each (100 Hz), a 50-reading
    wait after each; one cycle of one move has a following-error spike and the arm dips
    towards the desk once."""
    rng = np.random.default_rng(seed)
    events: list[dict] = [{"t": 0.0, "type": "run_started", "cycle_s": CYCLE_S,
                           "velocity_window_s": WINDOW_S, "virtual_time": True}]
    t = 0.0
    joints = np.zeros(ARM.dof)
    spike_move, spike_cycle = moves // 2 + 1, cycles // 3
    dip_move = moves
    for m in range(1, moves + 1):
        step = m
        target = joints.copy()
        target[1] = 30.0 if m % 2 else -30.0
        target[3] = 60.0 if m == dip_move else 20.0
        events.append({"t": round(t, 6), "type": "step_started", "step": step, "kind": "move",
                       "label": f"move {m}", "location": f"x.yaml:{m}:3"})
        events.append({"t": round(t, 6), "type": "move_planned", "step": step,
                       "target_deg": [round(x, 3) for x in target],
                       "velocity_limit_deg_s": [30.0] * ARM.dof})
        start = joints.copy()
        for k in range(cycles):
            t += CYCLE_S + rng.uniform(0, 0.002)
            s = 0.5 - 0.5 * np.cos(np.pi * (k + 1) / cycles)
            planned = start + s * (target - start)
            measured = planned + rng.normal(0, 0.02, ARM.dof)
            if m == spike_move and k == spike_cycle:
                measured[4] += 3.25                  # one cycle far off: must stay exact
            events.append({"t": round(t, 6), "type": "setpoint", "step": step,
                           "plan_t": round(k * CYCLE_S, 3),
                           "planned_deg": [round(x, 3) for x in planned],
                           "measured_deg": [round(x, 3) for x in measured],
                           "planned_vel_deg_s": [0.0] * ARM.dof, "state": [16] * ARM.dof})
        joints = target
        events.append({"t": round(t, 6), "type": "step_finished", "step": step,
                       "status": "passed", "duration_s": cycles * CYCLE_S})
        events.append({"t": round(t, 6), "type": "step_started", "step": step + 1000,
                       "kind": "wait", "label": "dwell", "location": f"x.yaml:{m}:9"})
        for _ in range(50):
            t += CYCLE_S
            events.append({"t": round(t, 6), "type": "measurement", "step": step + 1000,
                           "joints_deg": [round(x, 3) for x in joints],
                           "state": [32] * ARM.dof})
        events.append({"t": round(t, 6), "type": "step_finished", "step": step + 1000,
                       "status": "passed", "duration_s": 0.5})
    events.append({"t": round(t, 6), "type": "run_finished", "status": "passed"})
    return events


def all_readings(events: list[dict]) -> dict[str, np.ndarray]:
    cycles = [e for e in events if e["type"] in ("setpoint", "measurement")]
    return {"t": np.array([e["t"] for e in cycles]),
            "step": np.array([e["step"] for e in cycles]),
            "streamed": np.array([e["type"] == "setpoint" for e in cycles]),
            "planned": np.array([e.get("planned_deg", [np.nan] * ARM.dof) for e in cycles]),
            "measured": np.array([e.get("measured_deg", e.get("joints_deg")) for e in cycles])}


@pytest.fixture(scope="module")
def long_run() -> list[dict]:
    return synthetic_run(moves=8, cycles=900)


def test_extremes_of_a_decimated_run_are_exact(long_run):
    data = from_records({}, long_run, arm=ARM)
    r = all_readings(long_run)
    assert data.reading_count == len(r["t"]) > 2 * MAX_POINTS
    error = np.abs(r["planned"] - r["measured"])
    worst = np.nanmax(error, axis=0)
    np.testing.assert_array_equal(data.overview.worst_error_deg, worst)
    assert worst[4] > 3.2                                   # the spike is the worst
    points = kinematics.point_positions(kinematics.Chain.from_arm(ARM),
                                        np.radians(r["measured"]))
    for guard in ARM.workspace.guards:
        for point in guard.points:
            z = points[point][..., 2]
            assert data.overview.lowest_mm[(guard.name, point)] == z.min()
            # The plotted line is decimated, yet its lowest point is the lowest reading.
            t, line = data.overview.line(f"guard.{guard.name}.{point}")
            assert len(t) <= MAX_POINTS and np.nanmin(line) == z.min()
    for i in range(ARM.dof):
        t, line = data.overview.line(f"error.{i}")
        assert len(t) <= MAX_POINTS and np.all(np.diff(t) > 0)
        assert np.nanmax(np.abs(line)) == worst[i]


def test_recomputed_move_figures_equal_a_recomputation_from_every_reading(long_run):
    # No report.json: the page recomputes every move's figures from the step summaries.
    data = from_records({}, long_run, arm=ARM)
    r = all_readings(long_run)
    moves = [s for s in data.steps if s.kind == "move"]
    assert len(moves) == 8
    for step in moves:
        idx = np.flatnonzero(r["streamed"] & (r["step"] == step.number))
        target = np.array(step.move["target_deg"])
        velocity = windowed_velocity(r["t"][idx], r["measured"][idx], WINDOW_S)
        expected = {
            "max_following_error_deg": np.abs(r["planned"][idx] - r["measured"][idx]).max(axis=0),
            "final_error_deg": np.abs(target - r["measured"][idx[-1]]),
            "peak_measured_velocity_deg_s": peak_abs(velocity)}
        got = recompute_move_figures(data, step)
        for key, values in expected.items():
            np.testing.assert_allclose(got[key], np.round(values, 3), atol=1e-9, err_msg=key)


def test_chunks_do_not_change_any_figure(long_run, monkeypatch):
    whole = from_records({}, long_run, arm=ARM)
    monkeypatch.setattr(readings_module, "CHUNK_READINGS", 97)
    chunked = from_records({}, long_run, arm=ARM)
    assert chunked.reading_count == whole.reading_count
    np.testing.assert_array_equal(chunked.overview.worst_error_deg,
                                  whole.overview.worst_error_deg)
    assert chunked.overview.lowest_mm == whole.overview.lowest_mm
    assert chunked.overview.periods_us == whole.overview.periods_us
    for step in whole.steps:
        assert recompute_move_figures(chunked, step) == recompute_move_figures(whole, step)
    parts = list(chunked.readings())
    assert len(parts) > 10 and max(len(p) for p in parts) <= 97
    streamed = Series.concatenate(parts, ARM.dof)
    monkeypatch.setattr(readings_module, "CHUNK_READINGS", 1_000_000)
    [single] = list(whole.readings())
    np.testing.assert_array_equal(streamed.measured, single.measured)
    np.testing.assert_allclose(streamed.measured_vel, single.measured_vel, atol=1e-9)


def test_loop_periods_are_an_exact_histogram(long_run):
    data = from_records({}, long_run, arm=ARM)
    r = all_readings(long_run)
    same = r["streamed"][1:] & r["streamed"][:-1] & (r["step"][1:] == r["step"][:-1])
    periods = np.diff(r["t"])[same]
    from seqrun.report.figures import period_stats

    stats = period_stats(data)
    assert stats["count"] == periods.size
    assert stats["median_ms"] == pytest.approx(np.median(periods) * 1e3, abs=1e-9)
    assert stats["p99_ms"] == pytest.approx(np.percentile(periods, 99) * 1e3, abs=1e-9)
    assert stats["max_ms"] == pytest.approx(periods.max() * 1e3, abs=1e-9)


def test_a_long_run_draws_its_page_with_exact_captions(long_run, tmp_path):
    folder = tmp_path / "run"
    folder.mkdir()
    (folder / "events.jsonl").write_text("".join(json.dumps(e) + "\n" for e in long_run))
    write_html(folder, arm=ARM)
    text = (folder / "report.html").read_text()
    worst = np.nanmax(np.abs(all_readings(long_run)["planned"][:, 4]
                             - all_readings(long_run)["measured"][:, 4]))
    assert f"worst |planned − measured| {worst:.3f}°" in text


def write_log(path: Path, moves: int, cycles: int) -> None:
    with open(path, "w") as f:
        for e in synthetic_run(moves, cycles):
            f.write(json.dumps(e, separators=(",", ":")) + "\n")


def test_loading_holds_no_reading_it_has_read(tmp_path, monkeypatch):
    # The memory of loading a run does not grow with its readings: six times the
    # readings (same steps) peak at about the same memory. (Loading every event at once
    # peaked at ~1.5 kB per reading.) Both runs are decimated (a short line is kept whole).
    monkeypatch.setattr(data_module, "MAX_POINTS", 600)
    peaks = []
    for cycles in (500, 500, 3_000):     # the first time imports and caches: not counted
        folder = tmp_path / f"c{cycles}"
        folder.mkdir(exist_ok=True)
        write_log(folder / "events.jsonl", moves=8, cycles=cycles)
        gc.collect()
        tracemalloc.start()
        data = load_run(folder, arm=ARM)
        peaks.append(tracemalloc.get_traced_memory()[1])
        tracemalloc.stop()
        assert data.reading_count == 8 * (cycles + 50)
        del data
    assert peaks[2] < 1.3 * peaks[1], [p / 1e6 for p in peaks]


@settings(max_examples=examples(60), deadline=None)
@given(st.integers(1, 9000), st.integers(1, 3000), st.integers(2, 400),
       st.integers(0, 2**32 - 1))
def test_envelope_keeps_every_extreme_and_gap_whatever_the_chunks(n, chunk, max_points, seed):
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.001, 0.02, n))
    y = rng.normal(0, 1, (n, 2))
    y[rng.integers(0, n)] = [40.0, -40.0]                      # a spike per line
    gap = rng.integers(0, n - n // 4 + 1)
    y[gap:gap + n // 4, 0] = np.nan                            # a long gap in line 0
    envelope = Envelope(2, max_points)
    for start in range(0, n, chunk):
        envelope.add(t[start:start + chunk], y[start:start + chunk])
    whole = Envelope(2, max_points)
    whole.add(t, y)
    for j, ((td, yd), (tw, yw)) in enumerate(zip(envelope.finish(), whole.finish())):
        np.testing.assert_array_equal(td, tw)
        np.testing.assert_array_equal(yd, yw)
        assert len(td) <= max(max_points, 2) and np.all(np.diff(td) > 0)
        assert set(td) <= set(t)
        assert np.nanmax(yd) == np.nanmax(y[:, j]) and np.nanmin(yd) == np.nanmin(y[:, j])
        if n <= max_points:
            np.testing.assert_array_equal(yd, y[:, j])
            continue
        # A bucket of time whose samples are all NaN is a gap on the plot.
        ids = np.floor((t - t[0]) / (BASE_WIDTH_S * 2.0 ** envelope.level)).astype(int)
        gaps = [k for k in np.unique(ids) if np.all(np.isnan(y[ids == k, j]))]
        assert np.isnan(yd).sum() == len(gaps)
