"""Dialogs: the engine's prompts to the technician (with an optional visible auto-confirm) and yes/no questions."""

from __future__ import annotations

import time
from collections.abc import Callable

from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.screen import ModalScreen
from textual.widgets import Button, Label, Static

from labctl.tui.operator import PromptRequest

ACTION_TITLES = {
    "mount_specimen": "Mount the specimen",
    "turn_knobs": "Turn the star knobs",
    "rotate_rollers": "Rotate the rollers",
    "strike": "Hit the upper disc",
    "unload": "Unload now",
    "confirm": "Please confirm",
}
REFUSALS = {"abort", "cancel", "no", "stop"}

DIALOG_CSS = """
PromptDialog, ConfirmDialog { align: center middle; }
PromptDialog > Vertical, ConfirmDialog > Vertical {
    width: 72; max-width: 95%; height: auto; border: thick $warning; background: $surface; padding: 1 2;
}
PromptDialog .title, ConfirmDialog .title { text-style: bold; color: $warning; width: 100%; }
PromptDialog .message, ConfirmDialog .message { margin: 1 0; width: 100%; }
PromptDialog .countdown { color: $text-muted; width: 100%; }
PromptDialog Horizontal, ConfirmDialog Horizontal { height: auto; width: 100%; }
PromptDialog Button, ConfirmDialog Button { margin-right: 2; }
"""


def prompt_title(action: str, hint: str = "") -> str:
    """The dialog's headline: what to do, or why to hit again."""
    if action == "strike" and hint:
        return f"Hit again: {hint}"
    return ACTION_TITLES.get(action, "Please confirm")


class PromptDialog(ModalScreen[str]):
    """One engine prompt: a button per choice (Enter takes the first, digits pick by number).

    ``auto_delay_s`` is asked every tick: a number means the first choice is taken by itself that many
    seconds after the dialog appeared (shown as a countdown); None means wait for the technician.
    """

    DEFAULT_CSS = DIALOG_CSS
    BINDINGS = [Binding(str(n), f"choose({n})", show=False) for n in range(1, 10)] + [
        # the run stays under control while the engine waits for an answer (a modal screen hides app keys)
        Binding(key, f"app.{action}", show=False) for key, action in (
            ("p", "pause"), ("a", "abort"), ("r", "verdict(False)"), ("y", "verdict(True)"), ("t", "auto_confirm"),
            ("q", "quit"))]

    def __init__(self, request: PromptRequest, hint: str = "",
                 auto_delay_s: Callable[[], float | None] = lambda: None) -> None:
        super().__init__()
        self.request, self.hint, self.auto_delay_s = request, hint, auto_delay_s
        self.shown_at = time.monotonic()
        self.closed = False

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label(prompt_title(self.request.action, self.hint), classes="title")
            yield Static(self.request.message, classes="message")
            with Horizontal():
                for i, choice in enumerate(self.request.choices):
                    variant = "error" if choice.lower() in REFUSALS else ("primary" if i == 0 else "default")
                    yield Button(f"{i + 1} {choice}", id=f"choice-{i}", variant=variant)
            yield Static("", classes="countdown", id="countdown")

    def on_mount(self) -> None:
        self.query_one("#choice-0", Button).focus()
        self.set_interval(0.1, self.tick)
        self.tick()

    def tick(self) -> None:
        if self.closed:
            return
        if self.request.done.is_set():  # withdrawn: the campaign is stopping
            self.close(self.request.answer or "")
            return
        delay = self.auto_delay_s()
        label = self.query_one("#countdown", Static)
        if delay is None:
            label.update("")
            return
        left = self.shown_at + delay - time.monotonic()
        if left <= 0:
            self.answer(self.request.choices[0])
        else:
            label.update(f"simulated rig: '{self.request.choices[0]}' by itself in {left:.0f} s  (t: auto-confirm off)")

    def restart_countdown(self) -> None:
        self.shown_at = time.monotonic()

    def answer(self, choice: str) -> None:
        if not self.request.done.is_set():
            self.request.reply(choice)
        self.close(choice)

    def close(self, choice: str) -> None:
        if not self.closed:
            self.closed = True
            self.dismiss(choice)

    def on_button_pressed(self, event: Button.Pressed) -> None:
        event.stop()
        index = int(str(event.button.id).rpartition("-")[2])
        self.answer(self.request.choices[index])

    def action_choose(self, number: int) -> None:
        if 1 <= number <= len(self.request.choices):
            self.answer(self.request.choices[number - 1])


class ConfirmDialog(ModalScreen[bool]):
    """A yes/no question before something that cannot be undone (abort, quit mid-run)."""

    DEFAULT_CSS = DIALOG_CSS
    BINDINGS = [Binding("y", "answer(True)", "yes"), Binding("n,escape", "answer(False)", "no")]

    def __init__(self, title: str, message: str) -> None:
        super().__init__()
        self.title_text, self.message = title, message

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label(self.title_text, classes="title")
            yield Static(self.message, classes="message")
            with Horizontal():
                yield Button("y yes", id="yes", variant="error")
                yield Button("n no", id="no", variant="primary")

    def on_mount(self) -> None:
        self.query_one("#no", Button).focus()

    def on_button_pressed(self, event: Button.Pressed) -> None:
        event.stop()
        self.dismiss(event.button.id == "yes")

    def action_answer(self, yes: bool) -> None:
        self.dismiss(yes)
