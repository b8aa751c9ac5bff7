"""Write the JSON Schemas of seqrun's files to docs/schema/ (editors validate YAML with them).

    .venv/bin/python tools/gen_schemas.py          # write
    .venv/bin/python tools/gen_schemas.py --check  # exit 1 if a committed schema is stale

Each YAML file names its schema on its first line, e.g. poses/*.yaml:
``# yaml-language-server: $schema=../docs/schema/pose.schema.json``.
To add a schema, add an entry to :data:`SCHEMAS`.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCHEMA_DIR = ROOT / "docs" / "schema"


def _pose_schema() -> dict:
    from seqrun.arm.poses import PoseFile

    return PoseFile.model_json_schema()


def _arm_schema() -> dict:
    from seqrun.arm.description import ArmDescription

    return ArmDescription.model_json_schema()


def _sequence_schema() -> dict:
    from seqrun.schema import sequence_json_schema

    return sequence_json_schema()


def _suite_schema() -> dict:
    from seqrun.sequence.suite import suite_json_schema

    return suite_json_schema()


#: File name in docs/schema/ -> function returning the schema (imports stay lazy, so one
#: module that does not import yet does not stop the others from being generated).
SCHEMAS: dict[str, Callable[[], dict]] = {
    "arm.schema.json": _arm_schema,
    "pose.schema.json": _pose_schema,
    "sequence.schema.json": _sequence_schema,
    "suite.schema.json": _suite_schema,
}


def render(schema: dict) -> str:
    """The file text: keys in pydantic's order (it follows the models), so diffs stay small."""
    return json.dumps(schema, indent=2, ensure_ascii=False) + "\n"


def generated() -> dict[str, str]:
    """File name -> text of every schema."""
    return {name: render(make()) for name, make in SCHEMAS.items()}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true",
                        help="do not write; exit 1 if a file differs from what would be written")
    parser.add_argument("--out", type=Path, default=SCHEMA_DIR, help="output directory")
    args = parser.parse_args(argv)
    stale = []
    for name, text in generated().items():
        path = args.out / name
        current = path.read_text(encoding="utf-8") if path.is_file() else None
        if current == text:
            continue
        if args.check:
            stale.append(name)
        else:
            args.out.mkdir(parents=True, exist_ok=True)
            path.write_text(text, encoding="utf-8")
            print(f"wrote {path}")
    if stale:
        print(f"stale schema(s) in {args.out}: {', '.join(stale)}; "
              f"run: python tools/gen_schemas.py", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
