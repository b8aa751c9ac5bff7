"""The committed JSON Schemas in docs/schema/ are what tools/gen_schemas.py generates."""

from __future__ import annotations

import importlib.util
import json

import pytest

from projecttree import ROOT


def _load_generator():
    spec = importlib.util.spec_from_file_location("gen_schemas", ROOT / "tools" / "gen_schemas.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


gen_schemas = _load_generator()


@pytest.mark.parametrize("name", sorted(gen_schemas.SCHEMAS))
def test_committed_schema_is_up_to_date(name):
    committed = ROOT / "docs" / "schema" / name
    assert committed.is_file(), "run: python tools/gen_schemas.py"
    assert committed.read_text(encoding="utf-8") == gen_schemas.generated()[name], (
        f"docs/schema/{name} is stale; run: python tools/gen_schemas.py")


def test_pose_and_arm_schemas_are_there():
    assert {"pose.schema.json", "arm.schema.json"} <= set(gen_schemas.SCHEMAS)
    pose = json.loads((ROOT / "docs" / "schema" / "pose.schema.json").read_text())
    assert pose["additionalProperties"] is False
    assert set(pose["required"]) == {"name", "arm", "joints_deg", "end_effector"}


def test_check_mode_reports_a_stale_file(tmp_path, capsys):
    assert gen_schemas.main(["--out", str(tmp_path)]) == 0
    assert gen_schemas.main(["--check", "--out", str(tmp_path)]) == 0
    (tmp_path / "pose.schema.json").write_text("{}\n")
    assert gen_schemas.main(["--check", "--out", str(tmp_path)]) == 1
    assert "pose.schema.json" in capsys.readouterr().err


def test_schema_comment_of_pose_files_points_at_the_schema():
    for pose_file in (ROOT / "poses").glob("*.yaml"):
        first = pose_file.read_text(encoding="utf-8").splitlines()[0]
        target = first.removeprefix("# yaml-language-server: $schema=")
        assert (pose_file.parent / target).resolve() == ROOT / "docs" / "schema" / "pose.schema.json"
