"""Issue 39, item 4: ``include: {file, with: {...}}`` makes a file a template.

An included file may declare ``params:`` of its own: the include gives their values under
``with:`` (typed as written, each checked against its declaration), the ones not given take
their defaults, and the template's ``${name}`` and ``params.NAME`` read them; the including
file's parameters stay its own. Every problem at file:line:col."""

from __future__ import annotations

from pathlib import Path

import pytest

from seqrun.errors import SequenceInvalid
from seqrun.sequence.loader import load_sequence

APPROACH = """\
name: Approach
description: Go to a pose at a speed, then check the tool's height.
params:
  to: {type: pose, default: totem}
  speed: {type: float, min: 0.1, max: 1.0, default: 0.5}
  floor_mm: {type: float, unit: mm, default: 40}
steps:
  - move: {pose: "${to}", velocity_scale: "${speed}", label: "to ${to}"}
  - check: "tool.z_mm > params.floor_mm"
"""


def campaign(project: Path, top: str, template: str = APPROACH) -> Path:
    sequences = project / "sequences"
    sequences.mkdir(parents=True, exist_ok=True)
    (sequences / "approach.yaml").write_text(template, encoding="utf-8")
    path = sequences / "top.yaml"
    path.write_text(top, encoding="utf-8")
    return path


def errors_of(path: Path) -> list[str]:
    with pytest.raises(SequenceInvalid) as caught:
        load_sequence(path)
    return [str(e) for e in caught.value.errors]


def test_an_include_gives_a_template_its_values_and_the_rest_take_defaults(project):
    path = campaign(project, """\
name: Top
params:
  slow: {type: float, default: 0.2}
steps:
  - reset
  - home
  - set_limits
  - include: {file: approach.yaml, with: {to: opsafe, speed: "${slow}"}}
  - include: {file: approach.yaml, with: {floor_mm: 100}}
""")
    loaded = load_sequence(path)
    moves = [s for s in loaded.steps if s.kind == "move"]
    checks = [s for s in loaded.steps if s.kind == "check"]
    assert [m.params.pose for m in moves] == ["opsafe", "totem"]
    assert [m.params.velocity_scale for m in moves] == [0.2, 0.5]
    assert [m.label for m in moves] == ["to opsafe", "to totem"]
    assert [c.param_values for c in checks] == [
        {"to": "opsafe", "speed": 0.2, "floor_mm": 40.0},
        {"to": "totem", "speed": 0.5, "floor_mm": 100.0}]
    assert all(c.param_types["floor_mm"] == ("number", "mm") for c in checks)
    # the including file's own parameters are its own again after the include
    assert loaded.param_values == {"slow": 0.2}


def test_the_with_values_are_checked_against_the_templates_declarations(project):
    path = campaign(project, """\
name: Top
steps:
  - include: {file: approach.yaml, with: {speed: 3.0, spede: 0.5, to: true}}
""")
    errors = errors_of(path)
    assert len(errors) == 3, errors  # (nothing of the template's steps on top of them)
    assert errors[0].endswith("top.yaml:3:50: with speed: 3.0 is above the maximum 1.0")
    assert "top.yaml:3:55: " in errors[1] and errors[1].endswith(
        "approach.yaml declares no parameter 'spede' (declared: to, speed, floor_mm)")
    assert errors[2].endswith("top.yaml:3:71: with to: expected a pose name, got true")


def test_with_on_a_file_without_params_and_a_value_without_default(project):
    plain = "name: Plain\nsteps:\n  - wait: 1\n"
    path = campaign(project, """\
name: Top
steps:
  - include: {file: approach.yaml, with: {to: opsafe}}
""", template=APPROACH.replace("default: 0.5}", "}"))
    (error,) = errors_of(path)
    assert "top.yaml:3:" in error and error.endswith(
        "approach.yaml has no default: give it with 'with: {speed: VALUE}'")
    (project / "sequences" / "plain.yaml").write_text(plain, encoding="utf-8")
    path.write_text("name: Top\nsteps:\n  - include: {file: plain.yaml, with: {x: 1}}\n",
                    encoding="utf-8")
    assert any("top.yaml:3:33:" in e and "declares no params: 'with' gives values to a "
               "template's" in e for e in errors_of(path))


def test_a_with_value_is_strictly_typed(project):
    path = campaign(project, """\
name: Top
steps:
  - include: {file: approach.yaml, with: {speed: [0.5]}}
""")
    assert any("top.yaml:3:" in e for e in errors_of(path))


def test_a_file_without_params_still_uses_the_including_sequences(project):
    inner = "name: Inner\nsteps:\n  - move: {pose: \"${target}\"}\n"
    (project / "sequences").mkdir(parents=True, exist_ok=True)
    (project / "sequences" / "inner.yaml").write_text(inner, encoding="utf-8")
    path = project / "sequences" / "top.yaml"
    path.write_text("name: Top\nparams:\n  target: {type: pose, default: opsafe}\nsteps:\n"
                    "  - reset\n  - home\n  - set_limits\n  - include: inner.yaml\n",
                    encoding="utf-8")
    loaded = load_sequence(path)
    assert [s.params.pose for s in loaded.steps if s.kind == "move"] == ["opsafe"]


def test_a_template_runs_in_the_dry_run(project, tmp_path):
    from simrun import run_on_sim

    campaign(project, """\
name: Top
steps:
  - reset
  - home
  - set_limits
  - include: {file: approach.yaml, with: {to: opsafe, floor_mm: -2000}}
  - include: {file: approach.yaml, with: {floor_mm: 5000}}
""")
    sim = run_on_sim("top", tmp_path, root=project)
    result = sim.outcome.result
    # the first include's check held with its floor, the second's failed with its own
    assert result.exit_code == 3, result.message
    assert result.message == "check failed: tool.z_mm > params.floor_mm"
    checks = [s for s in result.steps if s.kind == "check"]
    assert [c.status for c in checks] == ["passed", "failed"]
