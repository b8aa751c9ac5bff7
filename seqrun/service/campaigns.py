"""The campaign a command works in, and what it says: its arm file, its poses, its bus.

Every face finds these here: the campaign of the current directory (or ``--project``),
of a sequence, the arm file a command reads (``--arm``, else the campaign's, else the
shipped one), the pose search path. The arm context every command resolves once
(:mod:`seqrun.service.arm_context`) is built from these.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from seqrun.sequence.project import CONFIG_NAME

if TYPE_CHECKING:
    from seqrun.sequence.project import Project

__all__ = ["CONFIG_NAME", "campaign_here", "campaign_of", "pose_search_path"]

def campaign_of(path: Path, project_dir: Path | None = None) -> Project:
    """The campaign of a sequence (or folder) ``path``: ``project_dir`` if given, else the
    nearest one above it, else the nearest folder with ``arms/`` or ``poses/``."""
    from seqrun.sequence.project import project_for

    return project_for(path, project_dir)


def campaign_here(project_dir: Path | None = None) -> Project:
    """``--project DIR``, else the campaign of the current directory."""
    from seqrun.sequence.project import open_project, project_for

    return open_project(project_dir) if project_dir else project_for(Path.cwd())






def pose_search_path(poses_dir: Path) -> Any:
    """``--poses-dir`` as given, or for the default the poses of the campaign here (a
    campaign's poses/, then the shipped ones)."""
    from seqrun.defaults import DEFAULT_POSES_DIR

    if poses_dir != DEFAULT_POSES_DIR:
        return poses_dir
    return campaign_of(Path.cwd()).pose_path

