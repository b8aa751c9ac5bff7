"""Standard output for every command: no wrapping into pipes, quiet on a closed pipe.

``seqrun validate … | head`` closes the pipe early. Like other command-line tools, a command
then ends quietly with 141 (128 + SIGPIPE). A run never ends that way: its output is only
a view of the run, so a closed stdout is dropped and the run goes on to its normal end
(the Halt path included) and exit code. SIGPIPE itself stays ignored (Python's default):
the bus may be a socket, and a dropped peer there must be an error, not a silent death.

Light on purpose (no rich at import time): ``seqrun --help`` imports it.
"""

from __future__ import annotations

import os
import sys
from typing import Any

#: Exit status of a command whose stdout was closed (what a shell shows for SIGPIPE).
EXIT_BROKEN_PIPE = 141


class _GuardedStdout:
    """Wraps sys.stdout; on a broken pipe, points fd 1 at /dev/null, then either ends the
    command quietly (``exit_on_break``) or carries on with the output dropped."""

    def __init__(self, stream: Any) -> None:
        self._stream = stream
        self.exit_on_break = True
        self.broken = False

    def _broken(self) -> None:
        self.broken = True
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, self._stream.fileno())
            os.close(devnull)
        except (OSError, ValueError):
            pass
        if self.exit_on_break:
            raise SystemExit(EXIT_BROKEN_PIPE)

    def write(self, text: str) -> int:
        if self.broken:
            return len(text)
        try:
            return self._stream.write(text)
        except BrokenPipeError:
            self._broken()
            return len(text)

    def flush(self) -> None:
        if self.broken:
            return
        try:
            self._stream.flush()
        except BrokenPipeError:
            self._broken()

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stream, name)


def guard_stdout() -> _GuardedStdout:
    """Install the guard on sys.stdout (idempotent); returns it."""
    if not isinstance(sys.stdout, _GuardedStdout) and sys.stdout is not None:
        sys.stdout = _GuardedStdout(sys.stdout)
    return sys.stdout  # type: ignore[return-value]


def keep_running_on_broken_pipe() -> None:
    """From now on a closed stdout only drops the output (``seqrun run``)."""
    out = sys.stdout
    if isinstance(out, _GuardedStdout):
        out.exit_on_break = False


def fixed(x: float, decimals: int = 2, width: int = 0) -> str:
    """``x`` with ``decimals`` places; never ``-0.00``."""
    value = round(float(x), decimals)
    if value == 0:
        value = 0.0
    return f"{value:{width}.{decimals}f}"


def make_console(**kwargs: Any):
    """A rich Console on stdout; into a pipe or file it does not wrap lines."""
    from rich.console import Console

    console = Console(**kwargs)
    if not console.is_terminal:
        console.soft_wrap = True
    return console
