"""The ``seqrun`` program (``seqrun``, ``python -m seqrun``): Ctrl-C during start-up is one
line, exit 130; once the command has ended, Ctrl-C no longer changes its exit code.

Importing the command line (typer, rich, numpy, python-can, ruckig) takes a moment. A
Ctrl-C in that moment used to print a KeyboardInterrupt traceback. Nothing can have been
sent to any bus yet, so until the commands are loaded SIGINT ends the process at once with
one line and the operator-abort exit code; after that each command handles it.

numpy's BLAS (OpenBLAS) starts a thread pool per core at import unless told otherwise: a
large part of numpy's import time, for matrices (4x4, 6x7) far too small to gain from threads.
The program asks for one thread unless the environment already says how many.

Likewise it sets pydantic's documented switch ``PYDANTIC_DISABLE_PLUGINS`` unless the
environment sets it: third-party plugins have no place on the path that validates the arm's
and the sequences' files, and looking for them costs every process a read of every installed
package's entry points.
"""

from __future__ import annotations

import os
import signal
import sys

EXIT_OPERATOR_ABORT = 130   # seqrun.executor's, without importing it (the point is speed)
_MESSAGE = b"seqrun: interrupted during start-up; nothing was sent\n"


def _interrupted_during_start_up(signum, frame) -> None:
    os.write(2, _MESSAGE)
    os._exit(EXIT_OPERATOR_ABORT)


#: The command line being started; read by :mod:`seqrun.cli` when it is first imported, to
#: load only the module of the command given (see seqrun.cli.COMMAND_WORDS).
command_line: list[str] | None = None


def main(argv: list[str] | None = None) -> None:
    global command_line
    command_line = list(argv if argv is not None else sys.argv[1:])
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    os.environ.setdefault("PYDANTIC_DISABLE_PLUGINS", "__all__")
    previous = signal.signal(signal.SIGINT, _interrupted_during_start_up)
    try:
        from seqrun.cli import main as cli_main
    finally:
        signal.signal(signal.SIGINT, previous)
    try:
        cli_main(command_line)
    finally:
        # The command has decided its exit code and said so: a Ctrl-C while the process
        # ends (threads joined, files closed) changes neither (a run that faulted, exit 3,
        # was reported as killed by SIGINT, 130).
        signal.signal(signal.SIGINT, signal.SIG_IGN)


if __name__ == "__main__":  # pragma: no cover
    main()
