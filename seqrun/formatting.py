"""Numbers and file text in the operator's messages: short, exact enough, never ``-0``;
never a control sequence that rewrites the terminal."""

from __future__ import annotations

import re

#: C0 and C1 control characters, DEL, and the Unicode marks that reorder or hide text
#: (bidirectional overrides and isolates, zero-width characters).
_UNPRINTABLE = re.compile("[\x00-\x1f\x7f-\x9f\u200b-\u200f\u202a-\u202e\u2066-\u2069"
                          "\ufeff]")


def terminal_text(text: object) -> str:
    """Text from a file or another process (a name, a description, a record's field) as
    it may be printed: every control character shown escaped (``\\x1b``), so an escape
    sequence in a file cannot move the cursor, recolour or rewrite a line of ours."""
    return _UNPRINTABLE.sub(lambda m: f"\\x{ord(m.group()):02x}" if ord(m.group()) < 0x100
                            else f"\\u{ord(m.group()):04x}", str(text))


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
