"""The operator's yes/no questions on the terminal, and the signals that end one.

Every question of every command is asked here: "y" or "yes" is a yes, anything else a no;
an empty stdin (end of input: no operator, a closed pipe) is a "no", said on its own line,
with the same ending as declining (click's ``confirm`` said "Aborted!", exit 1: the code
of an invalid sequence). Before a run's own signal handlers are in place,
:func:`signals_end_the_question` turns SIGTERM, SIGHUP and SIGQUIT into
:class:`QuestionInterrupted` so that the command can end in one line, having sent nothing.
"""

from __future__ import annotations

import signal
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

#: What the operator reads when stdin ended instead of an answer.
END_OF_INPUT = "(no answer: end of input) no"

#: Signals that end a question before the run's handlers are in place (SIGINT is Ctrl-C:
#: a KeyboardInterrupt, which the commands already end in one line).
_ENDING = tuple(getattr(signal, name) for name in ("SIGTERM", "SIGHUP", "SIGQUIT")
                if hasattr(signal, name))


class QuestionInterrupted(BaseException):
    """A signal came while a command waited for the operator (a BaseException: no
    ``except Exception`` on the way swallows it)."""

    def __init__(self, signum: int) -> None:
        self.name = signal.Signals(signum).name
        super().__init__(self.name)


def ask(question: str, assume_yes: bool = False, *,
        say: Callable[..., Any] | None = None,
        read: Callable[[], str | None] | None = None) -> bool:
    """Ask ``question``; True for "y"/"yes". ``say(text, end=...)`` prints (default:
    stdout); ``read`` returns one line, "" at the end of input, None when a signal
    interrupted the read (both a no)."""
    def default_say(text: str, end: str = "\n") -> None:
        sys.stdout.write(text + end)
        sys.stdout.flush()

    say = say or default_say
    if assume_yes:
        say(f"{question} yes (--yes)")
        return True
    say(f"{question} [y/N] ", end="")
    if read is None:
        try:
            answer: str | None = sys.stdin.readline()
        except KeyboardInterrupt:
            answer = None
        except (OSError, ValueError):  # stdin closed or not readable: nobody to answer
            answer = ""
    else:
        answer = read()
    if answer == "":
        say(END_OF_INPUT)  # the question's line ends, and the reason is on it
        return False
    return answer is not None and answer.strip().lower() in ("y", "yes")


def ask_choice(question: str, choices: tuple[str, ...], *, say: Callable[..., Any],
               read: Callable[[], str | None]) -> str | None:
    """One of ``choices`` by its name or first letter (asked again for anything else);
    None at the end of input or a signal (no answer). Never answered by --yes."""
    keys = "/".join(c[0] for c in choices)
    while True:
        say(f"{question} [{keys}] ", end="")
        answer = read()
        if answer == "":
            say(END_OF_INPUT)
            return None
        if answer is None:
            return None
        given = answer.strip().lower()
        for choice in choices:
            if given in (choice, choice[0]):
                return choice
        say(f"Answer one of: {', '.join(f'{c[0]} ({c})' for c in choices)}.")


def ask_name(role: str | None, *, say: Callable[..., Any],
             read: Callable[[], str | None]) -> str | None:
    """Who answers a signed question: their name (asked again while empty); None at the
    end of input or a signal (no name: no signature, a no)."""
    as_what = f" ({role})" if role else ""
    while True:
        say(f"Signed by{as_what}, your name: ", end="")
        answer = read()
        if answer == "":
            say(END_OF_INPUT)
            return None
        if answer is None:
            return None
        name = " ".join(answer.split())
        if name:
            return name
        say("A signed answer needs the name of who gives it.")


@contextmanager
def signals_end_the_question() -> Iterator[None]:
    """SIGTERM, SIGHUP and SIGQUIT raise :class:`QuestionInterrupted` meanwhile (their
    default is to die without a word, leaving no trace of the run that was asked about)."""
    def interrupted(signum: int, frame: Any = None) -> None:
        raise QuestionInterrupted(signum)

    saved = {}
    try:
        for signum in _ENDING:
            saved[signum] = signal.signal(signum, interrupted)
    except ValueError:  # not the main thread: signals stay as they are
        pass
    try:
        yield
    finally:
        for signum, old in saved.items():
            signal.signal(signum, old)
