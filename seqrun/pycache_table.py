"""One table file in ``seqrun/__pycache__``: read whole or not at all, written atomically.

:mod:`seqrun.source_cache` and :mod:`seqrun.pattern_cache` keep what Python compiles at
every start (generated source, regular expressions) in such a file, like bytecode: a
header that names what the entries depend on, then the entries, marshalled. A file that
is missing, damaged or from another header reads as nothing (the process compiles as
without the table); a read-only installation writes nothing.
"""

from __future__ import annotations

import marshal
import os
import sys
from pathlib import Path
from typing import Any


def path(name: str) -> Path:
    """``seqrun/__pycache__/<name>.<interpreter tag>.marshal``."""
    return (Path(__file__).parent / "__pycache__"
            / f"{name}.{sys.implementation.cache_tag}.marshal")


def read(file: Path, header: object) -> object | None:
    """The entries kept in ``file`` under ``header``; None if there are none to trust."""
    try:
        data = file.read_bytes()
    except OSError:
        return None
    try:
        kept_header, entries = marshal.loads(data)
    except (EOFError, ValueError, TypeError):
        return None  # damaged, or not a (header, entries) pair
    return entries if kept_header == header else None


def write(file: Path, header: Any, entries: Any) -> None:  # marshallable values
    """Replace ``file`` with ``(header, entries)``: readers see the old table or the new one,
    whole. Nothing is written where the folder is read-only or ``marshal`` refuses an entry."""
    temporary = file.with_name(f"{file.name}.{os.getpid()}.tmp")
    try:
        file.parent.mkdir(exist_ok=True)
        temporary.write_bytes(marshal.dumps((header, entries)))
        os.replace(temporary, file)
    except (OSError, ValueError):
        try:
            temporary.unlink()
        except OSError:
            pass
