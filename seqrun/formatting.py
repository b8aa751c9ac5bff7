"""Numbers in the operator's messages: short, exact enough, never ``-0``."""

from __future__ import annotations


def format_number(value: float) -> str:
    """A number for messages: at most 3 decimals, no trailing zeros, no '-0'; a number
    below 0.001 keeps 3 significant digits (a tolerance of 1e-06 is not "0")."""
    value = float(value)
    if value != 0 and abs(value) < 0.001:
        return f"{value:.3g}"
    return f"{round(value, 3) + 0.0:g}"


def format_range(lo: float, hi: float) -> str:
    """``lo…hi`` for messages (numbers as :func:`format_number`)."""
    return f"{format_number(lo)}…{format_number(hi)}"
