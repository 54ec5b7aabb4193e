"""An operator seen by the twin: whoever answers the prompts (script, console, TUI), the simulated rig reacts.

When a ``rotate_rollers`` prompt is answered with anything but a refusal, the disc was lifted and the rollers
turned, so the twin redraws each roller's contact spot. Every other call passes straight through.
"""

from __future__ import annotations

from drivers.interfaces import Operator, OperatorAction
from drivers.sim.twin import RigTwin

REFUSALS = frozenset({"abort", "cancel", "skip", "no", "stop", "quit"})
RESEATING_ACTIONS: frozenset[str] = frozenset({"rotate_rollers", "mount_specimen"})


class TwinOperator:
    """Wraps the real operator; reseats the twin's rollers after a confirmed rotate (or mount) prompt."""

    def __init__(self, inner: Operator, twin: RigTwin) -> None:
        self.inner, self.twin = inner, twin

    def prompt(self, message: str, choices: tuple[str, ...] = ("ok",), action: OperatorAction = "confirm") -> str:
        answer = self.inner.prompt(message, choices, action)
        if action in RESEATING_ACTIONS and answer.lower() not in REFUSALS:
            self.twin.rotate_rollers()
        return answer

    def notify(self, message: str) -> None:
        self.inner.notify(message)

    def __getattr__(self, name: str) -> object:  # e.g. a ScriptedOperator's prompt log
        if name == "inner":
            raise AttributeError(name)
        return getattr(self.inner, name)
