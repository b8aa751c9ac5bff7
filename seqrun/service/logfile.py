"""Files of the run folder that fail quietly and leave only whole lines behind.

A full disk (or a pulled USB stick) must never disturb the control loop: writing is one
``os.write`` per line (no buffer that flushes half a line later), the first error stops
that file for good (no error per CAN frame), cuts a partly written line off again, and is
reported once through ``on_error``. Whole files (report.json, junit.xml) are written to a
temporary file and renamed; a failed write removes the temporary file.
"""

from __future__ import annotations

import errno
import os
from pathlib import Path
from typing import Callable

#: Every byte of the run folder goes through this (tests put a full disk in its place).
_write = os.write

ErrorHandler = Callable[[Path, OSError], None]


def _write_all(fd: int, data: bytes) -> None:
    """Write ``data`` completely; a short write is continued, an error raised."""
    view = memoryview(data)
    while view:
        n = _write(fd, view)
        if n <= 0:   # pragma: no cover - os.write raises rather than return 0
            raise OSError(errno.EIO, "write returned 0")
        view = view[n:]


class LineFile:
    """An append-only text file written a whole line at a time."""

    def __init__(self, path: Path, on_error: ErrorHandler) -> None:
        self.path = Path(path)
        self.on_error = on_error
        self.error: OSError | None = None
        self._size = 0
        self._fd: int | None = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)

    def write(self, text: str) -> bool:
        """Append ``text`` (whole lines); False once the file has failed."""
        if self._fd is None or self.error is not None:
            return False
        data = text.encode("utf-8")
        try:
            _write_all(self._fd, data)
        except OSError as exc:
            self._fail(exc)
            return False
        self._size += len(data)
        return True

    def _fail(self, exc: OSError) -> None:
        self.error = exc
        try:   # cut off what went out of a partly written line: readers see whole lines
            if self._fd is not None:
                os.ftruncate(self._fd, self._size)
        except OSError:
            pass
        self.on_error(self.path, exc)

    @property
    def ok(self) -> bool:
        return self.error is None

    def close(self) -> None:
        if self._fd is not None:
            try:
                os.close(self._fd)
            except OSError:
                pass
            self._fd = None


def write_whole(path: Path, text: str | bytes) -> OSError | None:
    """Replace ``path`` by ``text`` (or bytes) atomically; the error (nothing left behind)
    or None."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    fd = None
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        _write_all(fd, text.encode("utf-8") if isinstance(text, str) else bytes(text))
        os.close(fd)
        fd = None
        os.replace(tmp, path)
        return None
    except OSError as exc:
        if fd is not None:
            try:
                os.close(fd)
            except OSError:
                pass
        try:
            os.unlink(tmp)
        except OSError:
            pass
        return exc


def overwrite_in_place(path: Path, text: str) -> OSError | None:
    """Write ``text`` over the start of the existing file ``path`` and cut it there: no
    new block is needed when ``text`` is no longer than the file (a full disk can still
    take it). The error, or None; a text longer than the file is refused (ENOSPC)."""
    data = text.encode("utf-8")
    try:
        fd = os.open(path, os.O_WRONLY)
    except OSError as exc:
        return exc
    try:
        if len(data) > os.fstat(fd).st_size:
            return OSError(errno.ENOSPC, "no room for it in the file")
        view = memoryview(data)
        offset = 0
        while offset < len(data):  # the blocks exist already: pwrite, not the disk's _write
            offset += os.pwrite(fd, view[offset:], offset)
        os.ftruncate(fd, len(data))
        return None
    except OSError as exc:
        return exc
    finally:
        os.close(fd)
