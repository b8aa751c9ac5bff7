"""Compiled code of the source text that dataclasses and typing generate, kept between runs.

Every ``@dataclass`` writes its ``__init__``, ``__repr__``, ``__eq__`` (and, frozen,
``__setattr__``, ``__delattr__``, ``__hash__``) as Python source and compiles it when the
class is created; every string annotation that pydantic or typer resolves is compiled by
``typing.ForwardRef``. A ``seqrun validate`` process creates ~160 dataclasses (seqrun's
events and codec records, pydantic's, typer's) and ~1,000 forward references: compiling
that text was ~10 % of the instructions of the whole command, the same work in every
process, like compiling the modules themselves would be without ``__pycache__``.

:func:`install` makes ``dataclasses`` and ``typing`` compile through a table of code
objects loaded from ``seqrun/__pycache__`` (as ``.pyc`` files are; each entry unmarshalled
when first used), keyed by the exact source text; text not in the table is compiled as
before and the table is written back at exit (not when bytecode writing is off:
``PYTHONDONTWRITEBYTECODE``). A code object depends only on its text, its file name
(``<string>``) and the compiler flags (none: no module routed here uses ``__future__``
imports), so the functions and classes made are the same as without the table.
``collections.namedtuple`` (its ``__new__``) and
``inspect.get_annotations`` (string annotations) evaluate text too: their ``eval`` goes
through the table the same way. Nothing else is kept: no results, no validated data.
"""

from __future__ import annotations

import builtins
import marshal
import sys
from pathlib import Path

from seqrun import pycache_table

#: Table file format; a different Python (bytecode magic) makes the table start empty.
_FORMAT = 2
#: Most entries kept: beyond, the table is rewritten with what the last process used.
MAX_ENTRIES = 20_000

#: (mode, text) -> code object, or its marshalled bytes until first used: a process uses
#: only some of the entries (each command its own), and unmarshalling all of them cost more
#: than the start-up work the rest of the table saves (``seqrun validate``: ~18 M
#: instructions for the ~1,000 entries that every command together has made).
_codes: dict[tuple[str, str], object] = {}
_used: set[tuple[str, str]] = set()
_compiled = 0
_installed = False


def _magic() -> bytes:
    from importlib.util import MAGIC_NUMBER

    return MAGIC_NUMBER


def table_path() -> Path:
    return pycache_table.path("generated-code")


def _code(source: str, mode: str):
    key = (mode, source)
    code = _codes.get(key)
    if type(code) is bytes:
        try:
            code = _codes[key] = marshal.loads(code)
        except (EOFError, ValueError, TypeError):
            code = None  # a damaged entry: compiled again below
    if code is None:
        global _compiled
        code = _codes[key] = builtins.compile(source, "<string>", mode, dont_inherit=True)
        _compiled += 1
    _used.add(key)
    return code


def _exec(source, globals=None, locals=None, /):  # noqa: A002 (exec's own parameters)
    """``exec`` for the dataclasses module: its source text compiled through the table."""
    if type(source) is str:
        source = _code(source, "exec")
    return builtins.exec(source, globals, locals)


def _eval(source, globals=None, locals=None, /):  # noqa: A002 (eval's own parameters)
    """``eval`` for collections (namedtuple) and inspect (string annotations): through the
    table. eval skips leading spaces and tabs of a text before compiling it."""
    if type(source) is str:
        source = _code(source.lstrip(" \t"), "eval")
    return builtins.eval(source, globals, locals)


def _compile(source, filename, mode, flags=0, dont_inherit=False, optimize=-1, **kwargs):
    """``compile`` for the typing module (``ForwardRef``): through the table."""
    if (type(source) is str and filename == "<string>" and mode == "eval" and not flags
            and optimize == -1 and not kwargs):
        return _code(source, mode)
    return builtins.compile(source, filename, mode, flags, dont_inherit, optimize, **kwargs)


def _load(path: Path) -> None:
    table = pycache_table.read(path, (_FORMAT, _magic()))
    if type(table) is dict:  # else none, damaged or from another Python: start empty
        _codes.update(table)


def save() -> None:
    """Write the table back if this process compiled text it did not have."""
    if not _compiled or sys.dont_write_bytecode:
        return
    kept = _codes if len(_codes) <= MAX_ENTRIES else {k: _codes[k] for k in _used}
    table = {k: v if type(v) is bytes else marshal.dumps(v)  # type: ignore[arg-type]
             for k, v in kept.items()}
    pycache_table.write(table_path(), (_FORMAT, _magic()), table)


def install() -> None:
    """Route the compiling of dataclasses, typing, collections and inspect through the
    table (once per process)."""
    global _installed
    if _installed:
        return
    _installed = True
    import atexit
    import collections
    import dataclasses
    import inspect
    import typing

    _load(table_path())
    dataclasses.exec = _exec  # type: ignore[attr-defined]  # its module global, not builtins
    typing.compile = _compile  # type: ignore[attr-defined]
    collections.eval = _eval  # type: ignore[attr-defined]
    inspect.eval = _eval  # type: ignore[attr-defined]
    atexit.register(save)
