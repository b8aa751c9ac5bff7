"""Numbers and file text in the operator's messages: short, exact enough, never ``-0``;
never a control sequence that rewrites the terminal."""

from __future__ import annotations

import re

#: C0 and C1 control characters, DEL, and the Unicode marks that reorder or hide text
#: (bidirectional overrides and isolates, zero-width characters).
_UNPRINTABLE = re.compile("[\x00-\x1f\x7f-\x9f\u200b-\u200f\u202a-\u202e\u2066-\u2069"
                          "\ufeff]")
#: What a file's text may not hold: the control characters that move the cursor or
#: rewrite a line (NUL aside: it shows nothing, and a path that holds one is refused as such).
_CONTROL = re.compile("[\x01-\x08\x0b-\x1f\x7f-\x9f]")


def terminal_text(text: object, *, lines: bool = False) -> str:
    """Text from a file or another process (a name, a description, a record's field) as
    it may be printed: every control character shown escaped (``\\x1b``), so an escape
    sequence in a file cannot move the cursor, recolour or rewrite a line of ours.
    ``lines``: a message of several lines, its line breaks kept."""
    def escaped(match: re.Match[str]) -> str:
        char = match.group()
        if lines and char == "\n":
            return char
        return f"\\x{ord(char):02x}" if ord(char) < 0x100 else f"\\u{ord(char):04x}"

    return _UNPRINTABLE.sub(escaped, str(text))


def control_character(text: str) -> str | None:
    """The first C0 (NUL aside) or C1 control character or DEL in ``text`` other than a tab
    or a line break (a file's text may hold those; zero-width and bidirectional marks are text, only
    escaped when printed), shown escaped; None if none."""
    for match in _CONTROL.finditer(text):
        return terminal_text(match.group())
    return None


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
