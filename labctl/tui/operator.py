"""The technician at the screen as the engine's Operator: a prompt becomes a dialog and the engine waits for it.

``prompt`` is called in the engine's worker thread; it hands the request to the UI thread with
``call_from_thread`` and blocks until the dialog is answered. When the campaign is stopped or aborted from
the UI while a dialog is open, the waiting prompt ends with ``StopRequested`` so the engine finishes cleanly.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field

from drivers.errors import DeviceDisconnected, DeviceError
from drivers.interfaces import OperatorAction
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

    def reply(self, answer: str) -> None:
        if answer not in self.choices:
            raise ValueError(f"answer {answer!r} is not one of {list(self.choices)}")
        if not self.done.is_set():
            self.answer = answer
            self.done.set()

    def withdraw(self, status: str) -> None:
        if not self.done.is_set():
            self.cancelled = status
            self.done.set()


class TuiOperator:
    """Satisfies ``drivers.interfaces.Operator`` by asking through the app's dialogs.

    ``show`` runs in the UI thread and must display the request (and eventually call ``reply``);
    ``tell`` shows a notice. Both are the app's callbacks, so this class knows nothing of widgets.
    """

    name = "operator@tui"

    def __init__(self, call_in_ui: Callable[..., object], show: Callable[[PromptRequest], object],
                 tell: Callable[[str], object]) -> None:
        self._call, self._show, self._tell = call_in_ui, show, tell
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
        request = PromptRequest(message, tuple(choices), action)
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
