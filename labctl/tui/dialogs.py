"""Dialogs: the engine's prompts to the technician (with an optional visible auto-confirm) and yes/no questions."""

from __future__ import annotations

import math
import time
from collections.abc import Callable

from textual import events
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.screen import ModalScreen
from textual.widgets import Button, Input, Label, Static

from labctl.tui.footer import KeyFooter
from labctl.tui.operator import PromptRequest
from labctl.tui.plots import FrfPlots, TracePlot
from labctl.tui.state import reason_text
from labctl.tui.stepfrf import StepFrf

ACTION_TITLES = {
    "mount_specimen": "Mount the specimen",
    "turn_knobs": "Turn the star knobs",
    "rotate_rollers": "Rotate the rollers",
    "strike": "Hit the upper disc",
    "unload": "Unload now",
    "confirm": "Please confirm",
}
REFUSALS = {"abort", "cancel", "no", "stop"}


def show_text(widget: Static, text: str) -> None:
    """Put ``text`` in ``widget`` only when it differs from what it shows: every update lays out and redraws the
    screen (under a dialog, the dimmed screen beneath too), and the countdowns ask ten times a second."""
    if widget.content != text:
        widget.update(text)

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
ReviewDialog { align: center bottom; background: $background 20%; }
ReviewDialog > KeyFooter { dock: bottom; }
ReviewDialog.-short .hint { display: none; }
ReviewDialog > Vertical {
    width: 100; max-width: 98%; height: auto; border: thick $success; background: $surface; padding: 0 2;
}
ReviewDialog.-flagged > Vertical { border: thick $error; }
ReviewDialog .title { text-style: bold; color: $success; width: 100%; }
ReviewDialog.-flagged .title { color: $error; }
ReviewDialog .message { margin: 0 0 1 0; width: 100%; }
ReviewDialog Horizontal { height: auto; width: 100%; }
ReviewDialog Button { margin-right: 2; }
ReviewDialog Input { display: none; }
ReviewDialog.-reason Input { display: block; }
ReviewDialog .countdown { color: $text-muted; width: 100%; }
ReviewDialog #gate-frf { height: 12; width: 100%; border: round $primary; }
ReviewDialog.-narrow #gate-coh-plot { display: none; }
ReviewDialog.-short #gate-frf { display: none; }
"""


def prompt_title(action: str, hint: str = "") -> str:
    """The dialog's headline: what to do, or why to hit again."""
    if action == "strike" and hint:
        return f"Hit again: {hint}"
    return ACTION_TITLES.get(action, "Please confirm")


class PromptDialog(ModalScreen[str]):
    """One engine prompt: a button per choice (Enter takes the highlighted first, digits pick by number). No
    letter answers a prompt: ``y`` is the gate's accept, so it never also continues past a drift or an abort.

    ``auto_delay_s`` is asked every tick: a number means the first choice is taken by itself that many
    seconds after the dialog appeared (shown as a countdown); None means wait for the technician.
    A verdict on an impact (the monitor's ``r``/``y``) is not taken here: the engine would apply it only after
    the prompt, to whatever impact is the latest by then.
    """

    DEFAULT_CSS = DIALOG_CSS
    BINDINGS = [Binding(str(n), f"choose({n})", show=False) for n in range(1, 10)] + [
        # the run stays under control while the engine waits for an answer (a modal screen hides app keys)
        Binding(key, f"app.{action}", show=False) for key, action in (
            ("p", "pause"), ("a", "abort"), ("t", "auto_confirm"), ("q", "quit"), ("question_mark", "help"))]

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
            show_text(label, "")
            return
        left = self.shown_at + delay - time.monotonic()
        if left <= 0:
            self.answer(self.request.choices[0])
        else:
            show_text(label, f"simulated rig: '{self.request.choices[0]}' by itself in {left:.0f} s  "
                             "(t: auto-confirm off)")

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
    """A question before something that cannot be undone (abort, quit mid-run). It is confirmed by its own key
    (``x`` for abort, ``q`` for quit), never by ``y``: no key confirms two different dialogs."""

    DEFAULT_CSS = DIALOG_CSS
    BINDINGS = [Binding("n,escape", "answer(False)", "no")]

    def __init__(self, title: str, message: str, yes_key: str = "x", yes_label: str = "yes") -> None:
        super().__init__()
        self.title_text, self.message, self.yes_key, self.yes_label = title, message, yes_key, yes_label

    @property
    def asks(self) -> str:
        """What the header says while this question is open."""
        return f"QUESTION: {self.title_text} ({self.yes_key} {self.yes_label} · n no)"

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label(self.title_text, classes="title")
            yield Static(self.message, classes="message")
            with Horizontal():
                yield Button(f"{self.yes_key} {self.yes_label}", id="yes", variant="error")
                yield Button("n no, go on", id="no", variant="primary")

    def on_key(self, event: events.Key) -> None:
        if event.key == self.yes_key:
            event.stop()
            self.dismiss(True)

    def on_mount(self) -> None:
        self.query_one("#no", Button).focus()

    def on_button_pressed(self, event: Button.Pressed) -> None:
        event.stop()
        self.dismiss(event.button.id == "yes")

    def action_answer(self, yes: bool) -> None:
        self.dismiss(yes)


def review_title(request: PromptRequest) -> str:
    """The gate's headline: which blow, and what the checks made of it."""
    r = request.review
    assert r is not None
    where = f"Step {r.step} impact {r.attempt}"
    if r.checks_accepted:
        return f"{where}: CLEAN — accept (y) or reject (r)?"
    return f"{where}: FLAGGED ({reason_text(r.reasons)}) — reject (r) or accept anyway (y)?"


def review_body(request: PromptRequest) -> str:
    """What the technician judges by, besides the plots: peak force, pulse width and the checks' reasons."""
    r = request.review
    assert r is not None
    said = "passed every check" if r.checks_accepted else f"the checks reject it: {reason_text(r.reasons)}"
    return (f"series {r.series} run {r.run} · peak {r.peak_force_n:.0f} N · pulse {r.pulse_width_s * 1e3:.2f} ms"
            f" · {said}.")


class ReviewDialog(ModalScreen[str]):
    """The per-hit gate: accept or reject the blow just stored; overriding the checks asks for a reason.

    Sits at the bottom of the screen so the impact plots stay visible, and draws the step's FRF so far
    (``frf``: the accepted blows and this one; not on short terminals). ``auto_delay_s`` as for
    ``PromptDialog``, but only a clean blow is ever accepted by itself; a flagged one waits for a person.
    """

    DEFAULT_CSS = DIALOG_CSS
    BINDINGS = [Binding("y", "choose('accept')", "accept"), Binding("r", "choose('reject')", "reject"),
                Binding("escape", "back", "back", show=False)] + [
        Binding(key, f"app.{action}", label) for key, action, label in (
            ("p", "pause", "pause"), ("a", "abort", "abort"), ("t", "auto_confirm", "auto"), ("q", "quit", "quit"),
            ("question_mark", "help", "keys"))]
    HORIZONTAL_BREAKPOINTS = [(0, "-narrow"), (120, "-wide")]
    VERTICAL_BREAKPOINTS = [(0, "-short"), (36, "-tall")]

    def __init__(self, request: PromptRequest, auto_delay_s: Callable[[], float | None] = lambda: None,
                 frf: StepFrf | None = None) -> None:
        super().__init__()
        assert request.review is not None
        self.request, self.auto_delay_s, self.frf = request, auto_delay_s, frf
        self.shown_at = time.monotonic()
        self.closed = False
        self.touched = False  # the technician started answering: no countdown any more
        self.pending: str | None = None  # the override waiting for its reason
        self.note = ""  # what the reason line says (e.g. that a reason is needed)

    @property
    def clean(self) -> bool:
        return bool(self.request.review and self.request.review.checks_accepted)

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label(review_title(self.request), classes="title")
            yield Static(review_body(self.request), classes="message")
            yield Static("Its force and response are in the impact panel above (range use on its lower border); "
                         "the next blow is armed only after your verdict.", classes="message hint")
            with Horizontal(id="gate-frf"):
                yield TracePlot("", "f [Hz]", "|H1| [(m/s²)/N]", id="gate-frf-plot")
                yield TracePlot("", "f [Hz]", "coherence", id="gate-coh-plot")
            with Horizontal():
                yield Button("y accept", id="accept", variant="success" if self.clean else "default")
                yield Button("r reject", id="reject", variant="default" if self.clean else "error")
            yield Input(placeholder="why? (Enter to confirm, Esc to go back)", id="reason")
            yield Static("", classes="countdown", id="countdown")
        yield KeyFooter()  # the gate covers the screen's footer: it shows the keys that work here

    def on_mount(self) -> None:
        self.set_class(not self.clean, "-flagged")
        self.query_one("#accept" if self.clean else "#reject", Button).focus()
        self.show_frf()
        self.set_interval(0.1, self.tick)
        self.tick()

    def show_frf(self) -> None:
        """|H1| and coherence of the step so far over the monitor's fixed span (hidden when there is none)."""
        panel = self.query_one("#gate-frf", Horizontal)
        if self.frf is None:
            panel.display = False
            return
        panel.border_title = self.frf.title()
        plots = FrfPlots(self.query_one("#gate-frf-plot", TracePlot), self.query_one("#gate-coh-plot", TracePlot))
        plots.show(self.frf.frequencies_hz, self.frf.h1_magnitude, self.frf.coherence, self.frf.channels, math.nan,
                   (), "")

    def tick(self) -> None:
        if self.closed:
            return
        if self.request.done.is_set():  # withdrawn: the campaign is stopping
            self.finish()
            return
        label = self.query_one("#countdown", Static)
        if self.pending is not None:
            show_text(label, self.note or f"{self.pending} overrides the checks: type the reason, Enter (Esc: back)")
            return
        delay = self.auto_delay_s()
        if not self.clean or delay is None or self.touched:
            show_text(label, "waiting for your verdict"
                      + ("" if self.clean else " (a flagged hit never accepts itself)"))
            return
        left = self.shown_at + delay - time.monotonic()
        if left <= 0:
            self.request.reply("accept", automatic=True)
            self.finish()
        else:
            show_text(label, f"simulated rig: a clean hit is accepted by itself in {left:.0f} s  (t: auto-confirm off)")

    def restart_countdown(self) -> None:
        self.shown_at = time.monotonic()

    def action_choose(self, verdict: str) -> None:
        self.touched = True
        if (verdict == "accept") != self.clean:  # an override: the reason first
            self.pending, self.note = verdict, ""
            self.add_class("-reason")
            self.query_one("#reason", Input).focus()
            self.tick()
            return
        self.request.reply(verdict)
        self.finish()

    def action_back(self) -> None:
        self.pending = None
        self.remove_class("-reason")
        self.query_one("#accept" if self.clean else "#reject", Button).focus()
        self.tick()

    def on_input_submitted(self, event: Input.Submitted) -> None:
        event.stop()
        reason = event.value.strip()
        if self.pending is None:
            return
        if not reason:
            self.note = f"an override needs a reason: type why you {self.pending} this hit, then Enter (Esc: back)"
            self.tick()
            return
        self.request.reply(self.pending, reason)
        self.finish()

    def on_button_pressed(self, event: Button.Pressed) -> None:
        event.stop()
        self.action_choose(str(event.button.id))

    def finish(self) -> None:
        if not self.closed:
            self.closed = True
            self.dismiss(self.request.answer or "")


KEYS = (
    ("s", "start the campaign (when not started with --autostart)"),
    ("p", "pause / resume: the engine holds before it arms the next blow"),
    ("a", "abort: asks first (x aborts, n goes on); the file keeps every impact"),
    ("y / r", "in the gate: accept / reject the blow just taken (an override asks why)"),
    ("1-9, Enter", "in a prompt: pick a choice by number; Enter takes the highlighted one"),
    ("t", "auto-confirm on/off (simulated rig only)"),
    ("o", "browse a campaign file"),
    ("q", "quit: mid-run it asks first (q again quits, the file stays resumable)"),
    ("?", "this help"),
)


class HelpScreen(ModalScreen[None]):
    """``?``: every key and what it does (one meaning per key)."""

    DEFAULT_CSS = """
    HelpScreen { align: center middle; }
    HelpScreen > Vertical { width: 90; max-width: 98%; height: auto; border: thick $primary; background: $surface;
        padding: 0 1; }
    HelpScreen .title { text-style: bold; width: 100%; }
    """
    BINDINGS = [Binding("escape,question_mark,enter", "close", "close")]

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label("Keys (Esc or ? closes)", classes="title")
            yield Static("\n".join(f"{k:>10}  {what}" for k, what in KEYS), markup=False)

    def action_close(self) -> None:
        self.dismiss(None)
