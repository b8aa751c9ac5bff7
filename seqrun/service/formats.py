"""The file formats as the faces publish them: the JSON Schema of sequence, arm and pose
files (editors validate YAML with them) and their Markdown references."""

from __future__ import annotations

from typing import Any

__all__ = ["FORMATS", "format_reference", "format_schema"]

#: The file formats seqrun reads, as ``seqrun schema`` names them.
FORMATS = ("sequence", "arm", "pose")


def format_schema(kind: str) -> dict[str, Any]:
    """The JSON Schema of a file format (``sequence``, ``arm``, ``pose``)."""
    if kind == "sequence":
        from seqrun.schema import sequence_json_schema

        return sequence_json_schema()
    if kind == "arm":
        from seqrun.arm.description import ArmDescription

        return ArmDescription.model_json_schema()
    from seqrun.arm.poses import PoseFile

    return PoseFile.model_json_schema()


def format_reference(kind: str) -> str:
    """The Markdown reference of a file format (for sequences: docs/sequence-format.md)."""
    from seqrun.sequence.reference import (arm_reference_markdown, pose_reference_markdown,
                                           reference_markdown)

    return {"sequence": reference_markdown, "pose": pose_reference_markdown,
            "arm": arm_reference_markdown}[kind]()
