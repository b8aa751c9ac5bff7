"""Questions for the operator as events: a run's ``confirm`` steps, step mode's before-step
question, clearing a fault latched before the run.

A question is published (``confirm_requested``) and answered by any face from any thread
(:meth:`Questions.answer`); a stop request or an abort withdraws it (a "no"). Part of the
arm session (:mod:`seqrun.service.session`).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass

from seqrun.errors import Refused

#: How often a waiting question looks for a stop request that answers it "no" (s).
POLL_S = 0.05


@dataclass
class Question:
    id: str
    text: str
    step: bool = False
    yes: bool | None = None
    #: A signed question: a yes needs the name of who gives it (kept in ``name``).
    sign: bool = False
    role: str | None = None
    name: str | None = None
    #: A question with choices (e.g. retry, skip, abort): a yes names one of them (kept in
    #: ``choice``); a no (or the withdrawal) chooses none.
    choices: tuple[str, ...] = ()
    choice: str | None = None

    def __post_init__(self) -> None:
        self.answered = threading.Event()


class Questions:
    """The open questions of one session.

    :param publish: the session's ``publish(type, **fields)``.
    :param stop_pending: whether a stop request is posted for the activity asking (a
        pending abort or STOP answers "no" at once).
    """

    def __init__(self, publish: Callable[..., None], stop_pending: Callable[[], bool],
                 started_by: Callable[[], str | None] = lambda: None) -> None:
        self._publish = publish
        self._stop_pending = stop_pending
        self._started_by = started_by
        self._lock = threading.Lock()
        self._open: dict[str, Question] = {}
        self._ids = 0

    def ask(self, text: str, *, step: bool = False) -> bool:
        """Publish ``text`` and wait for the answer (or the withdrawal: no)."""
        return bool(self._wait(Question("", text, step)).yes)

    def ask_signed(self, text: str, role: str | None) -> str | None:
        """A signed question: the name of who answered yes, None for a no."""
        q = self._wait(Question("", text, sign=True, role=role))
        return q.name if q.yes else None

    def ask_choice(self, text: str, choices: tuple[str, ...]) -> str | None:
        """A question with ``choices``: the one chosen, None for a no or the withdrawal."""
        q = self._wait(Question("", text, choices=tuple(choices)))
        return q.choice if q.yes else None

    def _wait(self, q: Question) -> Question:
        with self._lock:
            self._ids += 1
            q.id = f"q{self._ids}"
            self._open[q.id] = q
        by = self._started_by()  # who started the run the question is about
        signed = {"sign": True, **({"role": q.role} if q.role else {})} if q.sign else {}
        chosen = {"choices": list(q.choices)} if q.choices else {}
        self._publish("confirm_requested", question_id=q.id, text=q.text, **signed, **chosen,
                      **({"started_by": by} if by is not None else {}))
        while not q.answered.wait(POLL_S):
            # A stop request posted meanwhile (abort, STOP) answers no at once.
            if self._stop_pending():
                self._resolve(q, False)
        return q

    def answer(self, question_id: str, yes: bool, name: str | None = None,
               choice: str | None = None) -> None:
        """Answer a ``confirm_requested`` question (any thread); a signed one's yes with
        the ``name`` of who gives it, a yes to a question with choices with the ``choice``.
        Refused: unknown or already answered question, a signed yes without a name, a yes
        without one of the choices, a choice to a question without them (the question
        stays open)."""
        with self._lock:
            q = self._open.get(question_id)
        if q is None:
            raise Refused(f"answer: no open question {question_id!r}")
        if not isinstance(yes, bool):
            raise Refused(f"answer: yes must be true or false, got {yes!r}")
        if q.sign and yes:
            given = " ".join(name.split()) if isinstance(name, str) else ""
            if not given:
                raise Refused("answer: a signed question needs the name of who answers")
            q.name = given
        if q.choices and yes:
            if choice not in q.choices:
                raise Refused(f"answer: choose one of {', '.join(q.choices)}, got {choice!r}")
            q.choice = choice
        elif choice is not None and not q.choices:
            raise Refused(f"answer: question {question_id!r} offers no choices")
        self._resolve(q, yes)

    def step(self) -> None:
        """In step mode: let the next step start (answers its before-step question yes)."""
        with self._lock:
            waiting = [q for q in self._open.values() if q.step]
        if not waiting:
            raise Refused("step: no step is waiting to start")
        for q in waiting:
            self.answer(q.id, True)

    def withdraw(self) -> None:
        """Every open question answered "no" (the activity was stopped)."""
        with self._lock:
            open_ = list(self._open.values())
        for q in open_:
            self._resolve(q, False)

    def pending(self) -> dict[str, str]:
        """Questions waiting for an answer: id -> text."""
        with self._lock:
            return {q.id: q.text for q in self._open.values()}

    def _resolve(self, q: Question, yes: bool) -> None:
        with self._lock:
            if self._open.pop(q.id, None) is None:
                return
            q.yes = yes
        self._publish("confirm_answered", question_id=q.id, yes=yes,
                      **({"name": q.name} if q.sign and yes else {}),
                      **({"choice": q.choice} if q.choice is not None and yes else {}))
        q.answered.set()


class SessionAttended:
    """Signed confirms, breakpoints and on_fail: pause asked through the session's questions (the
    console's dialog): never answered by an ``assume_yes`` (:mod:`seqrun.steps.context`,
    ``AttendedQuestions``)."""

    #: Where its answers come from (an on_fail: pause's operator_choice event says).
    where = "console"

    def __init__(self, questions: Questions) -> None:
        self._questions = questions

    def sign(self, prompt: str, role: str | None) -> str | None:
        return self._questions.ask_signed(prompt, role)

    def breakpoint(self, prompt: str) -> bool:
        return self._questions.ask(prompt)

    def choose(self, prompt: str, choices: tuple[str, ...]) -> str | None:
        return self._questions.ask_choice(prompt, choices)
