"""The technician at the screen as the engine's Operator: a prompt becomes a dialog and the engine waits for it.

``prompt`` and ``review_impact`` are called in the engine's worker thread; they hand the request to the UI
thread (queued behind the events, never blocking on the UI) and block until the dialog is answered or the
prompt is withdrawn (the engine arms the next blow only after that). When the campaign is stopped or aborted from
the UI while a dialog is open, the waiting prompt ends with ``StopRequested`` so the engine finishes cleanly.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from drivers.errors import DeviceDisconnected, DeviceError
from drivers.interfaces import REVIEW_CHOICES, ImpactReview, OperatorAction
from labctl.engine import StopRequested


@dataclass
class PromptRequest:
    """One question to the technician; ``answer`` is set once, from the UI thread."""

    message: str
    choices: tuple[str, ...]
    action: str
    answer: str | None = None
    cancelled: str | None = None  # the stop status when the prompt was withdrawn
    done: threading.Event = field(default_factory=threading.Event)
    review: ImpactReview | None = None  # set for the per-hit gate: the blow the verdict is about
    reason: str = ""  # the technician's reason for a verdict (required when it overrides the checks)
    automatic: bool = False  # answered by the auto-accept countdown, not by a person

    def reply(self, answer: str, reason: str = "", automatic: bool = False) -> None:
        if answer not in self.choices:
            raise ValueError(f"answer {answer!r} is not one of {list(self.choices)}")
        if not self.done.is_set():
            self.answer, self.reason, self.automatic = answer, reason, automatic
            self.done.set()

    def withdraw(self, status: str) -> None:
        if not self.done.is_set():
            self.cancelled = status
            self.done.set()


class TuiOperator:
    """Satisfies ``drivers.interfaces.Operator`` by asking through the app's dialogs.

    ``show`` runs in the UI thread and must display the request (and eventually call ``reply``);
    ``tell`` shows a notice. Both are the app's callbacks, so this class knows nothing of widgets.
    With ``reviews_hits`` every stored blow is put to the technician (``review_impact``); without it the
    checks' verdicts stand.
    """

    name = "operator@tui"

    def __init__(self, call_in_ui: Callable[..., object], show: Callable[[PromptRequest], object],
                 tell: Callable[[str], object], reviews_hits: bool = False, arm_grace_s: float = 0.0,
                 held: Callable[[], bool] = lambda: False) -> None:
        self._call, self._show, self._tell = call_in_ui, show, tell
        self.reviews_hits = reviews_hits
        self.arm_grace_s = arm_grace_s  # after a person's verdict: time for a `p` before the next blow is armed
        self._held = held  # a pause or stop is asked for: the engine holds at its next safe point, no grace needed
        self._wake = threading.Event()
        self._lock = threading.Lock()
        self._pending: PromptRequest | None = None
        self._stopped: str | None = None
        self.history: list[PromptRequest] = []

    @property
    def pending(self) -> PromptRequest | None:
        return self._pending

    def prompt(self, message: str, choices: tuple[str, ...] = ("ok",), action: OperatorAction = "confirm") -> str:
        if not choices:
            raise DeviceError(self.name, "prompt", f"no choices offered for {message!r}")
        return self._ask(PromptRequest(message, tuple(choices), action))

    def review_impact(self, review: ImpactReview) -> tuple[str, str] | None:
        """The technician's verdict on a stored blow: ("accept" | "reject", reason), or None when the checks'
        verdict stands (no gate, or a clean blow accepted by the visible auto-accept countdown)."""
        if not self.reviews_hits:
            return None
        request = PromptRequest(review.message(), REVIEW_CHOICES, "review_impact", review=review)
        answer = self._ask(request)
        if request.automatic:
            return None
        self._grace()  # the engine arms only after this: a pause pressed just after `y` holds it
        return answer, request.reason or default_reason(review, answer)

    def _grace(self) -> None:
        """Wait ``arm_grace_s`` after a person's verdict, or until a pause or stop is asked for (``wake``): the
        engine then holds at its next safe point, before arming, so the rest of the grace has nothing to wait for."""
        deadline = time.monotonic() + self.arm_grace_s
        self._wake.clear()
        while not (self._stopped or self._held()) and (left := deadline - time.monotonic()) > 0:
            self._wake.wait(left)
            self._wake.clear()

    def wake(self) -> None:
        """A pause or stop was just asked for (UI thread): end a grace in progress at once."""
        self._wake.set()

    def verdicts(self, review: ImpactReview) -> dict[int, bool]:
        """The technician's answers on the blows of ``review``'s step so far: attempt → accepted."""
        where = (review.series, review.run, review.step)
        return {r.review.attempt: r.answer == "accept" for r in list(self.history)
                if r.review is not None and r.answer is not None
                and (r.review.series, r.review.run, r.review.step) == where}

    def _ask(self, request: PromptRequest) -> str:
        with self._lock:
            if self._stopped:
                raise StopRequested(self._stopped)
            self._pending = request
        self.history.append(request)
        try:
            try:
                self._call(self._show, request)
            except RuntimeError as exc:  # the app is no longer running
                raise DeviceDisconnected(self.name, "prompt", f"the screen is closed ({exc})") from None
            request.done.wait()
        finally:
            with self._lock:
                self._pending = None
        if request.cancelled is not None:
            raise StopRequested(request.cancelled)
        assert request.answer is not None
        return request.answer

    def notify(self, message: str) -> None:
        self._tell(message)

    def stop(self, status: str = "interrupted") -> None:
        """Withdraw the open prompt (if any) and refuse further ones: the engine is being stopped."""
        with self._lock:
            self._stopped = self._stopped or status
            pending = self._pending
        if pending is not None:
            pending.withdraw(self._stopped)
        self._wake.set()


def default_reason(review: ImpactReview, answer: str) -> str:
    """The stored reason of a verdict that agrees with the checks (an override always carries the technician's)."""
    if answer == "accept":
        return "confirmed by the operator: passed the checks" if review.checks_accepted else "accepted by the operator"
    flagged = ", ".join(review.reasons)
    return f"confirmed by the operator: {flagged}" if not review.checks_accepted and flagged else \
        "rejected by the operator"
