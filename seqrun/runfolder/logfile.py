"""Files of the run folder that fail quietly and leave only whole lines behind.

A full disk (or a pulled USB stick) must never disturb the control loop: writing is one
``os.write`` per line (no buffer that flushes half a line later), the first error stops
that file for good (no error per CAN frame), cuts a partly written line off again, and is
reported once through ``on_error``. Whole files (report.json, junit.xml) are written to a
temporary file and renamed; a failed write removes the temporary file.

:class:`GzipLineFile` is the compressed kind (the CAN trace: one gzip stream, which
python-can's readers, ``zcat`` and ``zgrep`` read). Lines are gathered in memory and
compressed a block at a time: :meth:`GzipLineFile.flush` compresses the block in one call
and ends a deflate block on a line boundary (a sync flush), so the file always decompresses
to whole lines up to its last flush, and a crash loses at most the block since then; an
error cuts the file back to that point. (Compressing every line by itself cost one zlib
call per CAN frame: most of the trace's CPU.)
"""

from __future__ import annotations

import errno
import gzip
import os
import zlib
from pathlib import Path
from typing import Callable, Iterable, Iterator

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


class _AppendOnlyFile:
    """What both kinds share: the file opened for appending, its first error reported once
    and cut back to ``_size`` (the bytes on disk that end on a whole line)."""

    def __init__(self, path: Path, on_error: ErrorHandler) -> None:
        self.path = Path(path)
        self.on_error = on_error
        self.error: OSError | None = None
        self._size = 0
        self._fd: int | None = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)

    def _fail(self, exc: OSError) -> None:
        self.error = exc
        try:   # cut off what went out after the last whole line: readers see whole lines
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


class LineFile(_AppendOnlyFile):
    """An append-only text file written a whole line at a time."""

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


class GzipLineFile(_AppendOnlyFile):
    """An append-only gzip file written a whole line at a time, readable (whole lines) up
    to the last :meth:`flush`: a run killed between two flushes loses only what came
    after the last one. Closing ends the gzip stream (its trailer).

    The lines since the last flush wait in memory and are compressed together; a block
    that grows past :data:`BLOCK_BYTES` is compressed early (not yet flushed) so that the
    memory held stays small whatever the caller's flushing."""

    #: zlib's default: most of level 9's ratio on CAN traces at a fraction of its time.
    LEVEL = 6
    #: Lines held uncompressed at most (bytes of text) before they go to the compressor.
    BLOCK_BYTES = 256 * 1024

    def __init__(self, path: Path, on_error: ErrorHandler) -> None:
        super().__init__(path, on_error)   # (_size: the bytes on disk at the last flush)
        self._written = 0       # bytes on disk
        self._pending = False   # lines written since the last flush
        self._block: list[str] = []   # lines not yet given to the compressor
        self._block_chars = 0
        self._z = zlib.compressobj(self.LEVEL, zlib.DEFLATED, 16 + zlib.MAX_WBITS)

    def write(self, text: str) -> bool:
        """Append ``text`` (whole lines); False once the file has failed."""
        if self._fd is None or self.error is not None:
            return False
        self._pending = True
        self._block.append(text)
        self._block_chars += len(text)
        if self._block_chars >= self.BLOCK_BYTES:
            return self._put(self._compress_block())
        return True

    def _compress_block(self) -> bytes:
        """The compressor's output for the lines held (they leave memory)."""
        if not self._block:
            return b""
        data = "".join(self._block).encode("utf-8")
        self._block.clear()
        self._block_chars = 0
        return self._z.compress(data)

    def flush(self) -> bool:
        """Put every line written so far on disk, decodable; False once failed."""
        if self._fd is None or self.error is not None:
            return False
        if not self._pending:
            return True
        self._pending = False
        if not self._put(self._compress_block() + self._z.flush(zlib.Z_SYNC_FLUSH)):
            return False
        self._size = self._written
        return True

    def _put(self, data: bytes) -> bool:
        if not data:
            return True
        assert self._fd is not None
        try:
            _write_all(self._fd, data)
        except OSError as exc:
            self._fail(exc)
            return False
        self._written += len(data)
        return True

    def close(self) -> None:
        if self._fd is None:
            return
        if self.error is None:
            self._put(self._compress_block() + self._z.flush(zlib.Z_FINISH))
        super().close()


def write_whole(path: Path, text: str | bytes) -> OSError | None:
    """Replace ``path`` by ``text`` (or bytes) atomically; the error (nothing left behind)
    or None."""
    return write_streamed(path, (text,))


def write_streamed(path: Path, parts: Iterable[str | bytes]) -> OSError | None:
    """Replace ``path`` atomically by the texts (or bytes) of ``parts``, written as they
    come (a large page never whole in memory); the error (nothing left behind) or None.
    Any other exception from ``parts`` removes the temporary file and goes on."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    fd = None
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        for part in parts:
            _write_all(fd, part.encode("utf-8") if isinstance(part, str) else bytes(part))
        os.close(fd)
        fd = None
        os.replace(tmp, path)
        return None
    except BaseException as exc:
        if fd is not None:
            try:
                os.close(fd)
            except OSError:
                pass
        try:
            os.unlink(tmp)
        except OSError:
            pass
        if isinstance(exc, OSError):
            return exc
        raise


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


def read_lines(path: Path) -> Iterator[bytes]:
    """The lines of a run-folder file as written, plain or gzip (``.gz``), including one
    cut short (a killed run, a full disk): what decodes, up to its last whole line."""
    path = Path(path)
    if path.suffix != ".gz":
        with open(path, "rb") as f:
            for line in f:
                if line.endswith(b"\n"):
                    yield line
        return
    with gzip.open(path, "rb") as f:
        try:
            for line in f:
                if line.endswith(b"\n"):
                    yield line
        except (EOFError, zlib.error, gzip.BadGzipFile):
            return   # the end of what got to disk
