"""Where the shipped arm descriptions, poses and sequences are, installed or not.

They live in the repository's top-level ``arms/``, ``poses/`` and ``sequences/`` folders
(the README's first command uses ``sequences/opsafe.yaml`` from the checkout). A wheel
carries them as the package data ``seqrun._shipped.<kind>`` (``pyproject.toml`` maps the
folders there), so an installed seqrun finds them from any directory, in its package's
folder; a source checkout on ``PYTHONPATH`` finds them beside the package.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

Kind = Literal["arms", "poses", "sequences"]

#: The package's folder (where pip puts the package data) and the checkout it was imported
#: from (meaningful only in a source tree).
_PACKAGE = Path(__file__).resolve().parent
_CHECKOUT = _PACKAGE.parent


def shipped_dir(kind: Kind) -> Path:
    """The folder of shipped ``kind`` files (a real directory either way)."""
    # In the regular package seqrun's folder, as importlib.resources.files("seqrun") would
    # give it for an installation on disk (seqrun._shipped.<kind> itself is a namespace
    # package, whose path is a multiplexed one); without importing importlib.resources
    # (zipfile, tempfile) in every command that reads an arm.
    installed = _PACKAGE / "_shipped" / kind
    if installed.is_dir():
        return installed
    return _CHECKOUT / kind  # a source checkout: the folders beside the package


def shipped_arm(name: str) -> Path | None:
    """The shipped arm file ``<name>.yaml``, or None."""
    path = shipped_dir("arms") / f"{name}.yaml"
    return path if path.is_file() else None


def shipped_arm_names() -> list[str]:
    return sorted(p.stem for p in shipped_dir("arms").glob("*.yaml"))


#: The arm of a sequence or campaign that names none.
DEFAULT_ARM_NAME = "lwa3"
