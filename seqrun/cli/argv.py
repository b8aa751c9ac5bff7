"""Command-line words rewritten before parsing: python-can's ``--bus-kwargs`` style.

python-can's tools take several ``KEY=VALUE`` after one ``--bus-kwargs`` (``python -m
can.viewer -i socketcand --bus-kwargs host=127.0.0.1 port=29536``); click options take
one value each. :func:`expand_bus_kwargs` turns the first form into repeated options; the
same for the joint angles after ``seqrun zero set --deg`` (negative numbers included), and
``--foxglove`` alone gets its default port (``--foxglove[=PORT]``).
No imports beyond the standard library: this runs before every command.
"""

from __future__ import annotations

import re
from collections.abc import Sequence

_OPTION = "--bus-kwargs"
_KEY_VALUE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*=")
_DEGREES = "--deg"
#: ``--foxglove`` alone serves on this port (seqrun.foxglove.DEFAULT_PORT); a port is
#: given as ``--foxglove=PORT``.
_FOXGLOVE, _FOXGLOVE_PORT = "--foxglove", "8766"
_NUMBER = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$")


def expand_bus_kwargs(args: Sequence[str]) -> list[str]:
    """``[..., "--bus-kwargs", "a=1", "b=2", ...]`` -> ``[..., "--bus-kwargs", "a=1",
    "--bus-kwargs", "b=2", ...]``: words that look like ``KEY=VALUE`` right after a
    ``--bus-kwargs`` value belong to it. Nothing after ``--`` is touched."""
    out: list[str] = []
    words = list(args)
    i = 0
    while i < len(words):
        word = words[i]
        out.append(word)
        i += 1
        if word == "--":
            out.extend(words[i:])
            break
        if word == _OPTION or word.startswith(_OPTION + "="):
            if word == _OPTION and i < len(words):
                out.append(words[i])  # its own value, whatever it is
                i += 1
            while i < len(words) and _KEY_VALUE.match(words[i]):
                out += [_OPTION, words[i]]
                i += 1
        elif word == _FOXGLOVE:   # an optional value: the next word is never it
            out[-1] = f"{_FOXGLOVE}={_FOXGLOVE_PORT}"
        elif word == _DEGREES:
            if i < len(words):
                out.append(words[i])  # its own value, whatever it is
                i += 1
            while i < len(words) and _NUMBER.match(words[i]):
                out += [_DEGREES, words[i]]
                i += 1
    return out
