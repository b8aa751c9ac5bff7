"""Shared by reset/home/halt: which modules a step addresses."""

from __future__ import annotations


def addressed_modules(params, arm) -> list[int] | None:
    """Module ids named by ``joints``; None for 'all' (one broadcast)."""
    if params.joints == "all":
        return None
    return [arm.joint(name).module for name in params.joints]


def addressed_text(params) -> str:
    """The modules a step addresses, for people: "all modules" or "j1, j2"."""
    return "all modules" if params.joints == "all" else ", ".join(params.joints)
