"""Shared by reset/home/halt: which modules a step addresses."""

from __future__ import annotations


def addressed_modules(params, arm) -> list[int] | None:
    """Module ids named by ``joints``; None for 'all' (one broadcast)."""
    if params.joints == "all":
        return None
    return [arm.joint(name).module for name in params.joints]
