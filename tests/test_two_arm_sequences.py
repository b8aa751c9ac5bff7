"""Two arms, one campaign (issue 28, item 2): steps name their arm, parallel blocks and
signal/wait_for put the arms' tracks on one time line, validation checks every track
against its own arm and the two arms' volumes against each other along both planned paths,
and the dry run runs both arms at one virtual time on two simulated buses."""

from __future__ import annotations

import threading

import numpy as np
import pytest
from typer.testing import CliRunner

from seqrun.arm.between_arms import base_transform, between_arms
from seqrun.arm.description import load_arm
from seqrun.arm.geometry import Geometry
from seqrun.cli import app
from seqrun.clock import LockstepClock
from seqrun.sequence.arm_tracks import load_tracks
from seqrun.sequence.project import open_project
from seqrun.service.arms_check import campaign_has_arms
from twoarmskit import check, copy_example, write
from seqrun.shipped import shipped_arm



@pytest.fixture
def campaign(tmp_path, monkeypatch):
    """A copy of the example campaign (arms A and B facing each other, 900 mm apart)."""
    return copy_example(tmp_path, monkeypatch)


# --------------------------------------------------------------------------- the examples
def test_the_example_is_valid_and_says_its_closest_approach(campaign):
    found = check(campaign / "sequences" / "hold_and_approach.yaml", dry_run=False)
    assert found.errors == []
    (between,) = found.between
    assert between.distance_mm > 100  # the hands stay well apart
    assert between.pair.startswith("A.") and "~B." in between.pair
    assert set(found.tracks.tracks) == {"A", "B"}


def test_the_crossing_example_is_refused_at_the_step_that_crosses(campaign):
    found = check(campaign / "sequences" / "paths_cross.yaml", dry_run=False)
    (error,) = found.errors
    text = (campaign / "sequences" / "paths_cross.yaml").read_text().splitlines()
    assert "B reaches over to where A holds" in text[error.line - 1 + 7] or \
        "B reaches over" in "\n".join(text[error.line - 1:error.line + 8])
    assert "the arms' paths cross" in error.message and "geometry margin" in error.message
    assert found.between[0].distance_mm < 0  # they would overlap
    assert found.dry_run is None  # nothing runs after a refusal


@pytest.mark.slow
def test_validate_cli_refuses_the_crossing_example_with_file_line_col(campaign):
    result = CliRunner().invoke(app, ["validate", "sequences/paths_cross.yaml", "--static"])
    assert result.exit_code == 1, result.output
    first = result.output.splitlines()[0]
    assert first.startswith("sequences/paths_cross.yaml:31:13: the arms' paths cross")
    assert "invalid (1 error" in result.output


# --------------------------------------------------------------------------- the format
SHORT = """\
name: Short
description: Both arms move a little, then one waits for the other.
steps:
  - parallel:
      - arm: A
        steps:
          - move: {joints: {j1: 10}, label: A turns}
          - signal: A_turned
      - arm: B
        steps:
          - wait_for: {event: A_turned, timeout_s: 20}
          - move: {joints: {j1: -10}, label: B turns}
  - move: {joints: {j1: 0}, arm: A, label: A back}
  - {arm: B, move: {joints: {j1: 0}, label: B back}}
"""


def test_steps_are_split_into_one_track_per_arm_with_the_order_in_them(campaign):
    path = write(campaign, "short.yaml", SHORT)
    tracks = load_tracks(path, project=open_project(campaign),
                         arm_paths={"A": shipped_arm("lwa3"), "B": shipped_arm("lwa3")}).tracks
    a = [(s.kind, s.title) for s in tracks["A"].steps]
    b = [(s.kind, s.title) for s in tracks["B"].steps]
    assert a[0] == ("move", "A turns") and ("signal", "signal A_turned") in a
    assert ("move", "A back") in a
    # B's "back" waits for A's "back" (the steps run in the order written)
    back = [k for k, _ in b].index("move", 2)
    assert b[back - 1][0] == "wait_for" and "arm A" in b[back - 1][1]
    assert tracks["A"].steps[0].location.line == 7


@pytest.mark.parametrize("steps, where, message", [
    ("  - move: {pose: totem, arm: C}\n", "4:30", "unknown arm 'C' (this campaign has arms A, B)"),
    ("  - {arm: 7, move: totem}\n", "4:11", "unknown arm '7'"),
    ("  - move: {pose: totem, arm: A}\n  - move: totem\n", "5:5",
     "which arm? this campaign has arms A, B"),
    ("  - parallel:\n      - {arm: A, steps: [wait: 1]}\n      - {arm: A, steps: [wait: 1]}\n",
     "6:15", "two branches on arm A (the other at line 5)"),
    ("  - parallel:\n      - arm: A\n        steps: [{move: {pose: totem, arm: B}}]\n",
     "6:43", "names arm B inside the branch of arm A"),
    ("  - wait_for: {event: nobody, arm: A}\n", "4:23", "no step of any arm signals 'nobody'"),
    ("  - wait_for: {event: later, arm: A}\n  - signal: {event: later, arm: B}\n", "4:23",
     "arm A would wait here for ever: 'later' is signalled at"),
    ("  - signal: {event: twice, arm: A}\n  - signal: {event: twice, arm: B}\n", "5:21",
     "'twice' is signalled twice"),
    ("  - parallel:\n      - {arm: A, steps: [wait: 30, signal: late]}\n"
     "      - {arm: B, steps: [{wait_for: {event: late, timeout_s: 5}}]}\n", "6:62",
     "'late' comes 30.00 s after arm B gets here (planned), later than timeout_s 5 s"),
    ("  - move: {pose: nowhere, arm: B}\n", "4:18", "unknown pose 'nowhere'"),
])
def test_bad_arm_steps_are_one_line_at_file_line_col(campaign, steps, where, message):
    path = write(campaign, "bad.yaml", "name: Bad\ndescription: x\nsteps:\n" + steps)
    found = check(path, dry_run=False)
    lines = [str(e) for e in found.errors]
    assert any(line.startswith(f"sequences/bad.yaml:{where}: ") and message in line
               for line in lines), lines


def test_a_one_arm_campaign_keeps_its_format_and_refuses_signal(tmp_path, monkeypatch):
    folder = tmp_path / "one"
    (folder / "sequences").mkdir(parents=True)
    (folder / "seqrun.toml").write_text('[campaign]\narm = "lwa3"\n')
    path = folder / "sequences" / "s.yaml"
    path.write_text("name: One\ndescription: x\nsteps:\n  - reset\n  - signal: go\n")
    monkeypatch.chdir(folder)
    assert campaign_has_arms(path) is None
    result = CliRunner().invoke(app, ["validate", "sequences/s.yaml", "--static"])
    assert result.exit_code == 1
    assert result.output.startswith("sequences/s.yaml:5:13: signal synchronises the arms")


# --------------------------------------------------------------------------- the dry run
def test_the_dry_run_runs_both_arms_at_one_virtual_time(campaign):
    path = write(campaign, "short.yaml", SHORT)
    found = check(path, started=True)
    assert found.errors == [] and found.dry_run is not None, found.errors
    arms = found.dry_run.outcome.arms
    assert found.dry_run.passed, {a: o.result.message for a, o in arms.items()}
    a_turns = next(s for s in arms["A"].result.steps if s.label == "A turns")
    b_turns = next(s for s in arms["B"].result.steps if s.label == "B turns")
    # B waited for A's signal: it starts when A's turn ends, on the one time base
    assert b_turns.started == pytest.approx(a_turns.finished, abs=0.03)
    a_back = next(s for s in arms["A"].result.steps if s.label == "A back")
    b_back = next(s for s in arms["B"].result.steps if s.label == "B back")
    assert b_back.started >= a_back.finished - 1e-9


def test_a_fault_on_one_arm_halts_both(campaign):
    path = write(campaign, "short.yaml", SHORT)
    found = check(path, started=True, faults=[("A", _fault("all:halt@0.5"))])
    run = found.dry_run
    assert run is not None and not run.passed
    a, b = run.outcome.arms["A"], run.outcome.arms["B"]
    assert a.result.exit_code == 3 and b.result.exit_code == 3
    assert b.halted_for == "A" and a.halted_for is None
    assert b.result.fault["halt_sent"]
    assert any("every arm was halted" in n for n in run.outcome.notes)


def test_halt_faulted_halts_only_the_faulted_arm_and_says_so(campaign):
    toml = campaign / "seqrun.toml"
    toml.write_text(toml.read_text().replace('# on_fault = "halt_faulted"',
                                             'on_fault = "halt_faulted"'))
    path = write(campaign, "apart.yaml", """\
name: Apart
description: Both arms move, nobody waits for the other.
steps:
  - parallel:
      - {arm: A, steps: [{move: {joints: {j1: 10}}}]}
      - {arm: B, steps: [{move: {joints: {j1: -10}}}]}
""")
    found = check(path, started=True, faults=[("A", _fault("all:halt@0.5"))])
    arms = found.dry_run.outcome.arms
    assert arms["A"].result.exit_code == 3
    # B's branch goes on; only the order's wait after the block meets A's end
    assert arms["B"].halted_for is None
    assert arms["B"].result.steps[0].status == "passed"
    assert any("only arm A was halted" in n for n in found.dry_run.outcome.notes)


def _fault(spec: str):
    from seqrun.sim.faults import parse_fault_spec

    return parse_fault_spec(spec)


@pytest.mark.slow
def test_the_example_dry_run_passes_with_b_waiting_for_a(campaign):
    found = check(campaign / "sequences" / "hold_and_approach.yaml")
    assert found.dry_run is not None and found.dry_run.passed
    a = {s.label: s for s in found.dry_run.outcome.arms["A"].result.steps}
    b = {s.label: s for s in found.dry_run.outcome.arms["B"].result.steps}
    assert b["B above the target"].started >= a["A to the hold pose"].finished - 1e-9
    assert a["A retreats"].started >= b["B backs off"].finished - 1e-9


# --------------------------------------------------------------------------- the cores
def test_between_arms_measures_in_the_facility_frame():
    arm = load_arm(shipped_arm("lwa3"))
    geometry = Geometry(arm)
    q = np.zeros((1, len(arm.joints)))  # straight up
    far = between_arms(("A", geometry, base_transform([0, 0, 0], [0, 0, 0])),
                       ("B", geometry, base_transform([1000, 0, 0], [0, 0, 180])), q, q)
    near = between_arms(("A", geometry, base_transform([0, 0, 0], [0, 0, 0])),
                        ("B", geometry, base_transform([150, 0, 0], [0, 0, 0])), q, q,
                        below_mm=60.0)
    widest = float(geometry.radii_mm.max())
    assert far[0].distance_mm == pytest.approx(1000 - 2 * widest, abs=1.0)
    assert far[1] is None
    assert near[0].distance_mm == pytest.approx(150 - 2 * widest, abs=1.5)
    assert near[1] is not None and near[1].index == 0


def test_the_lockstep_clock_moves_only_when_every_thread_sleeps():
    shared = LockstepClock()
    first, second = shared.view(), shared.view()
    seen: list[tuple[str, float]] = []

    def walk(name, view, steps):
        for dt in steps:
            view.sleep(dt)
            seen.append((name, round(view.now(), 6)))
        view.leave()

    threads = [threading.Thread(target=walk, args=("a", first, [0.3, 0.3, 0.3])),
               threading.Thread(target=walk, args=("b", second, [0.5, 0.5]))]
    for t in threads:
        t.start()
    for t in threads:
        t.join(5)
    assert [t for _, t in seen] == sorted(t for _, t in seen)
    assert sorted(seen) == [("a", 0.3), ("a", 0.6), ("a", 0.9), ("b", 0.5), ("b", 1.0)]


@pytest.mark.slow
def test_validating_the_campaign_folder_checks_each_file_as_it_runs(campaign):
    """A two-arm sequence as two arms; a fragment naming no arm (startup.yaml, included
    per arm) as one arm's sequence against the first arm's arm file."""
    result = CliRunner().invoke(app, ["validate", ".", "--static", "--json"])
    assert result.exit_code == 1, result.output
    import json

    rows = {r["file"]: r for r in json.loads(result.output)["results"]}
    assert rows["sequences/hold_and_approach.yaml"]["result"] == "valid"
    assert "between arms" in rows["sequences/hold_and_approach.yaml"][
        "lowest_guard_clearance_at"]
    assert rows["sequences/paths_cross.yaml"]["result"] == "invalid"
    assert rows["sequences/startup.yaml"]["result"] == "valid"
