"""The ``seqrun`` program's entry point: Ctrl-C during start-up is one line, exit 130.

Importing the command line (typer, rich, numpy, python-can, ruckig) takes about a second.
A Ctrl-C in that second used to print a KeyboardInterrupt traceback. Nothing can have been
sent to any bus yet, so until the commands are loaded SIGINT ends the process at once with
one line and the operator-abort exit code; after that each command handles it.

numpy's BLAS (OpenBLAS) starts a thread pool per core at import unless told otherwise: about
half of numpy's import time, for matrices (4x4, 6x7) far too small to gain from threads.
The program asks for one thread unless the environment already says how many. Likewise it
loads no pydantic plugins unless the environment asks for them (:mod:`seqrun.pydantic_plugins`).

The source text that dataclasses and typing compile at every start is compiled once and
kept like bytecode (:mod:`seqrun.source_cache`); so are the regular expressions that modules
compile when imported (:mod:`seqrun.pattern_cache`). Imports run without cyclic garbage
collection and what they made is frozen out of later collections (:mod:`seqrun.import_gc`).
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
    from seqrun import import_gc, pydantic_plugins

    import_gc.install()
    pydantic_plugins.install()
    from seqrun import pattern_cache, source_cache

    pattern_cache.install()
    source_cache.install()
    previous = signal.signal(signal.SIGINT, _interrupted_during_start_up)
    try:
        from seqrun.cli import main as cli_main
    finally:
        signal.signal(signal.SIGINT, previous)
    cli_main(command_line)


if __name__ == "__main__":  # pragma: no cover
    main()
