"""Compiled regular expressions, kept between runs like bytecode.

Modules compile their regular expressions when imported: logging, textwrap, json, email,
PyYAML's resolver and reader, typer's click, pydantic, numpy, seqrun's own. A ``seqrun
validate`` process compiles ~75 patterns that way, ~0.1 G instructions (PyYAML's set of
printable characters, ranges up to U+10FFFF, alone ~58 M): the same work in every process.

Compiling is two steps: ``re._compiler`` parses the pattern and generates the engine's code
(pure Python, the expensive part), then ``_sre.compile`` makes the pattern object from that
code. :func:`install` puts a table in front of the first step: for a (pattern, flags) seen
before, the arguments ``re._compiler.compile`` passed to ``_sre.compile`` (final flags,
code, group count, group names) are loaded from ``seqrun/__pycache__`` and passed again, so
the pattern object is the one normal compiling makes (equal to it: same code, flags, groups).
The arguments are recorded from the normal compile itself, not recomputed. Anything else
compiles as before: another Python (the table's header names the exact interpreter and
regular-expression engine), parsed subpatterns, the DEBUG flag, a pattern whose compiling
warned (the warning must come again), an entry ``_sre`` refuses. Written back at exit like
:mod:`seqrun.source_cache`'s table (not with ``PYTHONDONTWRITEBYTECODE``). Nothing else is
kept: no matches, nothing from the files seqrun reads.
"""

from __future__ import annotations

import sys
import threading
import types
from pathlib import Path
from re import _compiler, _constants  # type: ignore[attr-defined]

import _sre  # type: ignore[import-not-found]

from seqrun import pycache_table

#: Table file format.
_FORMAT = 1
#: Most entries kept: beyond, the table is rewritten with what the last process used.
MAX_ENTRIES = 5_000

#: (pattern, flags) -> (flags, code, groups, groupindex, indexgroup): _sre.compile's
#: arguments after the pattern. One table per pattern type: a str and a bytes key may hash
#: alike, and comparing them warns under ``python -b``.
_tables: dict[type, dict[tuple, tuple]] = {str: {}, bytes: {}}
_used: dict[type, set[tuple]] = {str: set(), bytes: set()}
_added = 0
_installed = False
_normal_compile = _compiler.compile
_recording = threading.local()
_warning_lock = threading.RLock()


def header() -> tuple:
    """What the table's entries depend on: this interpreter (its build included) and its
    regular-expression engine."""
    return (_FORMAT, sys.version, sys.hexversion, _sre.MAGIC, _sre.CODESIZE, sys.maxunicode)


def table_path() -> Path:
    return pycache_table.path("compiled-patterns")


def _recording_sre_compile(pattern, flags, code, groups, groupindex, indexgroup):
    """``_sre.compile`` as ``re._compiler`` sees it: also notes the arguments."""
    _recording.arguments = (flags, [int(c) for c in code], groups, dict(groupindex),
                            indexgroup)
    return _sre.compile(pattern, flags, code, groups, groupindex, indexgroup)


def recording_sre() -> types.ModuleType:
    """``_sre`` for ``re._compiler``'s module global: its ``compile`` also records the
    arguments; every other name is ``_sre``'s own."""
    module = types.ModuleType(_sre.__name__)
    module.__dict__.update(vars(_sre))
    module.compile = _recording_sre_compile  # type: ignore[attr-defined]
    return module


def compile(p, flags=0):  # noqa: A001 (re._compiler's name: it replaces that function)
    """``re._compiler.compile`` through the table."""
    kind = type(p)
    if (kind is not str and kind is not bytes) or type(flags) is not int \
            or flags & _constants.SRE_FLAG_DEBUG:
        return _normal_compile(p, flags)
    key = (p, flags)
    table = _tables[kind]
    entry = table.get(key)
    if entry is not None:
        final_flags, code, groups, groupindex, indexgroup = entry
        try:
            # a fresh dict, as each normal compile passes its own
            pattern = _sre.compile(p, final_flags, code, groups, dict(groupindex), indexgroup)
        except Exception:  # noqa: BLE001 (a damaged entry: compile normally, replace it)
            del table[key]
        else:
            _used[kind].add(key)
            return pattern
    return _compile_and_keep(p, flags, kind, key)


def _compile_and_keep(p, flags, kind, key):
    global _added
    warned = False
    with _warning_lock:
        import warnings

        warn = warnings.warn

        def noting_warn(message, category=None, stacklevel=1, source=None):
            nonlocal warned
            warned = True
            # this function, _compile_and_keep and compile: three frames more than the
            # normal path, so the warning names the same caller's line
            return warn(message, category, stacklevel + 3, source)

        _recording.arguments = None
        warnings.warn = noting_warn
        try:
            pattern = _normal_compile(p, flags)
        finally:
            if warnings.warn is noting_warn:
                warnings.warn = warn
    arguments, _recording.arguments = _recording.arguments, None
    if arguments is not None and not warned:
        _tables[kind][key] = arguments
        _used[kind].add(key)
        _added += 1
    return pattern


def _load(path: Path) -> None:
    tables = pycache_table.read(path, header())
    if type(tables) is not tuple or len(tables) != 2:
        return
    kept_str, kept_bytes = tables
    if type(kept_str) is not dict or type(kept_bytes) is not dict:
        return
    _tables[str].update(kept_str)
    _tables[bytes].update(kept_bytes)


def save() -> None:
    """Write the table back if this process compiled patterns it did not have."""
    if not _added or sys.dont_write_bytecode:
        return
    tables = tuple(table if len(table) <= MAX_ENTRIES else {k: table[k] for k in _used[kind]}
                   for kind, table in _tables.items())
    pycache_table.write(table_path(), header(), tables)


def install() -> None:
    """Route ``re``'s compiling through the table (once per process)."""
    global _installed
    if _installed:
        return
    _installed = True
    import atexit

    _load(table_path())
    _compiler._sre = recording_sre()
    _compiler.compile = compile
    atexit.register(save)
