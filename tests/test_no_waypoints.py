"""seqrun never asks ruckig for intermediate waypoints: the Community build solves
waypoint problems through a cloud API, and a plan must never leave this machine (nor
blend through waypoints: every move is planned from rest to rest, or to a stop).

Every Ruckig seqrun makes is watched while every shipped sequence is validated and the
thesis procedure runs on the simulator: none may be built for waypoints, none may get an
input with intermediate positions."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest
import ruckig
from typer.testing import CliRunner

from projecttree import ROOT
from seqrun.cli import app
from simrun import run_on_sim


class Watched:
    """ruckig.Ruckig as seqrun's planners see it, recording how it is built and asked."""

    made: list[tuple] = []
    inputs: list[list] = []

    def __init__(self, *args):
        Watched.made.append(args)
        self._ruckig = ruckig.Ruckig(*args)

    def calculate(self, inp, *rest):
        Watched.inputs.append([list(p) for p in inp.intermediate_positions])
        return self._ruckig.calculate(inp, *rest)

    def update(self, inp, *rest):
        Watched.inputs.append([list(p) for p in inp.intermediate_positions])
        return self._ruckig.update(inp, *rest)


@pytest.fixture
def watched(monkeypatch):
    Watched.made, Watched.inputs = [], []
    for module in ("seqrun.arm.planner", "seqrun.arm.cartesian"):
        monkeypatch.setattr(f"{module}.Ruckig", Watched)
    return Watched


def test_no_plan_of_any_shipped_sequence_uses_waypoints(watched, tmp_path):
    result = CliRunner().invoke(app, ["validate", str(ROOT / "sequences"), "--static"])
    assert result.exit_code == 0, result.output
    run = run_on_sim("thesis_procedure", tmp_path)
    assert run.outcome.result.exit_code == 0, run.outcome.result.message
    assert watched.made and watched.inputs          # the planners were watched
    assert all(len(args) == 1 for args in watched.made), watched.made  # dofs only
    assert all(points == [] for points in watched.inputs)


def test_no_source_mentions_ruckig_waypoints():
    """A second line of defence: no module sets intermediate positions or builds a
    Ruckig for waypoints (a second argument)."""
    for path in (ROOT / "seqrun").rglob("*.py"):
        text = path.read_text(encoding="utf-8")
        assert "intermediate_positions" not in text, path
        for node in ast.walk(ast.parse(text)):
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
                    and node.func.id == "Ruckig"):
                assert len(node.args) <= 1 and not node.keywords, \
                    f"{Path(path).relative_to(ROOT)}:{node.lineno}"


def test_the_thesis_procedure_takes_a_fifth_of_the_thesis_simulated_time(tmp_path):
    """bench/bench_thesis.py's comparison at virtual time (simulated seconds, exact, not
    a timing): the thesis' session against sequences/thesis_procedure.yaml, on the same
    simulator. The figure itself (real time) lives in bench/README.md."""
    import sys

    sys.path.insert(0, str(ROOT / "bench"))
    try:
        from bench_thesis import run_seqrun, run_thesis
    finally:
        sys.path.remove(str(ROOT / "bench"))
    from seqrun.clock import VirtualClock

    thesis = run_thesis(VirtualClock(), "test-thesis-ratio")
    seqrun = run_seqrun(VirtualClock(), tmp_path, 0)
    assert seqrun["status"] == "passed"
    assert seqrun["max_abs_error_deg"] < 1e-3 and thesis["max_abs_error_deg"] < 1e-3
    assert thesis["time_s"] / seqrun["time_s"] >= 5.0, (thesis["time_s"], seqrun["time_s"])
