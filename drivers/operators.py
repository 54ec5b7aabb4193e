"""Operators: a script that answers prompts by itself (CI, the simulator, campaigns) and a person at a terminal.

Both satisfy ``drivers.interfaces.Operator``: ``prompt(message, choices, action)`` returns one of ``choices``.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import TextIO

from drivers.errors import DeviceDisconnected, DeviceError
from drivers.interfaces import REVIEW_CHOICES, ImpactReview, OperatorAction

ReviewKey = tuple[int, int, int, int]
"""(series, run, step, attempt) of a blow."""

PromptCallback = Callable[[str, tuple[str, ...]], "str | None"]
"""Called with (message, choices) for a prompt of its action; returns the answer, or None for the default."""


@dataclass(frozen=True)
class PromptLog:
    """One prompt as it was shown and answered."""

    message: str
    choices: tuple[str, ...]
    action: str
    answer: str


@dataclass
class ScriptedOperator:
    """Answers every prompt without a person: a callback for its action, else the next scripted answer for
    that action, else the first choice (the confirmation). Every prompt and notice is recorded.

    ``reviews`` gives verdicts on chosen blows, keyed by (series, run, step, attempt): ("accept" or "reject",
    reason); every other blow keeps the checks' verdict. ``reviewed`` records each verdict given.
    """

    answers: Mapping[str, Iterable[str]] = field(default_factory=dict)
    reviews: Mapping[ReviewKey, tuple[str, str]] = field(default_factory=dict)
    reviewed: list[tuple[ReviewKey, str, str]] = field(default_factory=list)
    callbacks: dict[str, PromptCallback] = field(default_factory=dict)
    prompts: list[PromptLog] = field(default_factory=list)
    notices: list[str] = field(default_factory=list)
    name: str = "operator@script"

    def __post_init__(self) -> None:
        self._queues = {action: list(seq) for action, seq in self.answers.items()}

    def on(self, action: OperatorAction | str, callback: PromptCallback) -> None:
        """Act on every prompt tagged ``action`` (e.g. rotate a simulated rig's rollers)."""
        self.callbacks[action] = callback

    def prompt(self, message: str, choices: tuple[str, ...] = ("ok",), action: OperatorAction = "confirm") -> str:
        if not choices:
            raise DeviceError(self.name, "prompt", f"no choices offered for {message!r}")
        answer: str | None = None
        if action in self.callbacks:
            answer = self.callbacks[action](message, tuple(choices))
        queue = self._queues.get(action)
        if answer is None and queue:
            answer = queue.pop(0)
        answer = choices[0] if answer is None else answer
        if answer not in choices:
            raise DeviceError(self.name, "prompt", f"scripted answer {answer!r} is not one of {list(choices)}")
        self.prompts.append(PromptLog(message, tuple(choices), action, answer))
        return answer

    def notify(self, message: str) -> None:
        self.notices.append(message)

    def review_impact(self, review: ImpactReview) -> tuple[str, str] | None:
        """The scripted verdict on this blow, if the script names it (else the checks decide)."""
        key = (review.series, review.run, review.step, review.attempt)
        verdict = self.reviews.get(key)
        if verdict is None:
            return None
        if verdict[0] not in REVIEW_CHOICES:
            raise DeviceError(self.name, "review", f"scripted verdict {verdict[0]!r} is not one of {REVIEW_CHOICES}")
        self.reviewed.append((key, verdict[0], verdict[1]))
        self.prompts.append(PromptLog(review.message(), REVIEW_CHOICES, "review_impact", verdict[0]))
        return verdict

    def actions(self) -> list[str]:
        """The action tags of every prompt so far, in order."""
        return [p.action for p in self.prompts]


class ConsoleOperator:
    """A person at a terminal: the prompt is printed with its choices and answered by a line on stdin.

    An empty line takes the first choice; an answer may be the choice's number, its name or a unique prefix
    (case-insensitive). Closed input raises ``DeviceDisconnected``; ``max_attempts`` invalid answers raise
    ``DeviceError``. With ``reviews_impacts`` the engine asks for a verdict on every stored blow.
    """

    def __init__(self, stdin: TextIO | None = None, stdout: TextIO | None = None, max_attempts: int = 5,
                 reviews_impacts: bool = False) -> None:
        self.name = "operator@console"
        self.reviews_impacts = reviews_impacts  # asked accept/reject after every stored blow
        self._in, self._out, self._max = stdin or sys.stdin, stdout or sys.stdout, max_attempts

    def prompt(self, message: str, choices: tuple[str, ...] = ("ok",), action: OperatorAction = "confirm") -> str:
        if not choices:
            raise DeviceError(self.name, "prompt", f"no choices offered for {message!r}")
        menu = "  ".join(f"[{i}] {c}" for i, c in enumerate(choices, 1))
        self._out.write(f"\n{message}\n{menu}  (Enter = {choices[0]})\n")
        for _ in range(self._max):
            self._out.write("> ")
            self._out.flush()
            line = self._in.readline()
            if not line:
                raise DeviceDisconnected(self.name, "prompt", "input closed before an answer")
            answer = match_choice(line.strip(), choices)
            if answer is not None:
                return answer
            self._out.write(f"please answer one of: {', '.join(choices)}\n")
        raise DeviceError(self.name, "prompt", f"no valid answer after {self._max} attempts")

    def notify(self, message: str) -> None:
        self._out.write(f"{message}\n")
        self._out.flush()


def match_choice(text: str, choices: tuple[str, ...]) -> str | None:
    """The choice ``text`` names: empty = the first, a 1-based number, the name, or a unique prefix."""
    if not text:
        return choices[0]
    if text.isdigit() and 1 <= int(text) <= len(choices):
        return choices[int(text) - 1]
    low = text.lower()
    exact = [c for c in choices if c.lower() == low]
    if exact:
        return exact[0]
    prefixed = [c for c in choices if c.lower().startswith(low)]
    return prefixed[0] if len(prefixed) == 1 else None
