"""Choosing what to run (a shipped protocol or a file, the backend, the output file) and which file to open."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical, VerticalScroll
from textual.screen import ModalScreen, Screen
from textual.widgets import Button, Checkbox, Input, Label, OptionList, RadioButton, RadioSet, Static
from textual.widgets.option_list import Option

from labctl.errors import LabctlError
from labctl.protocol import load_protocol, shipped_protocols
from labctl.tui.footer import KeyFooter

if TYPE_CHECKING:
    from labctl.tui.app import TuiSettings

SETUP_CSS = """
SetupScreen { align: center middle; }
SetupScreen > VerticalScroll { width: 90; max-width: 100%; height: auto; max-height: 100%; border: round $primary;
                         padding: 0 1; }
SetupScreen OptionList { height: auto; max-height: 10; }
SetupScreen Horizontal { height: auto; }
SetupScreen .row-label { width: 16; padding: 1 1 0 0; }
SetupScreen Input { width: 1fr; }
SetupScreen #error { color: $error; height: auto; }
OpenFileScreen { align: center middle; }
OpenFileScreen > Vertical { width: 80; max-width: 100%; height: auto; border: thick $primary; padding: 1 2;
                            background: $surface; }
OpenFileScreen #error { color: $error; height: auto; }
"""


def _description(path: Path) -> str:
    try:
        return load_protocol(path).description
    except LabctlError:
        return "(not a valid protocol)"


class SetupScreen(Screen):
    """Pick a protocol and backend, then start; dismissed with the completed settings (None to quit)."""

    DEFAULT_CSS = SETUP_CSS
    BINDINGS = [Binding("ctrl+s", "start", "start"), Binding("escape", "cancel", "quit")]

    def __init__(self, settings: TuiSettings) -> None:
        super().__init__()
        self.settings = settings
        self.shipped = shipped_protocols()

    def compose(self) -> ComposeResult:
        with VerticalScroll():
            yield Label("[b]labctl[/b] · choose a protocol")
            yield OptionList(*[Option(f"{name}  [dim]{_description(p)}[/dim]", id=name)
                               for name, p in sorted(self.shipped.items())], id="protocols")
            with Horizontal():
                yield Static("or a file", classes="row-label")
                yield Input(placeholder="path/to/protocol.toml", id="protocol-path")
            with Horizontal():
                yield Static("backend", classes="row-label")
                with RadioSet(id="backend"):
                    yield RadioButton("sim (simulated rig)", value=self.settings.backend == "sim", id="sim")
                    yield RadioButton("hw (the real rig)", value=self.settings.backend == "hw", id="hw")
            with Horizontal():
                yield Static("campaign file", classes="row-label")
                yield Input(placeholder="<protocol>-<date>-<time>.h5", id="out")
            yield Checkbox("simulated rig: confirm prompts by themselves after a few seconds",
                           value=not self.settings.no_auto_confirm, id="auto")
            yield Static("", id="error")
            with Horizontal():
                yield Button("Start", id="start", variant="primary")
                yield Button("Open a campaign file…", id="open")
                yield Button("Quit", id="quit", variant="error")
        yield KeyFooter()

    def on_mount(self) -> None:
        options = self.query_one("#protocols", OptionList)
        names = sorted(self.shipped)
        options.highlighted = names.index("quick_check") if "quick_check" in names else 0
        options.focus()

    def on_option_list_option_selected(self, event: OptionList.OptionSelected) -> None:
        self.action_start()

    def on_button_pressed(self, event: Button.Pressed) -> None:
        if event.button.id == "start":
            self.action_start()
        elif event.button.id == "open":
            self.app.action_browse()
        else:
            self.action_cancel()

    def action_cancel(self) -> None:
        self.dismiss(None)

    def action_start(self) -> None:
        from labctl.tui.app import DEFAULT_AUTO_CONFIRM_S

        path = self.query_one("#protocol-path", Input).value.strip()
        if not path:
            options = self.query_one("#protocols", OptionList)
            if options.highlighted is None:
                self.query_one("#error", Static).update("choose a protocol or give a file")
                return
            path = str(self.shipped[str(options.get_option_at_index(options.highlighted).id)])
        out = self.query_one("#out", Input).value.strip()
        try:
            protocol = load_protocol(path)
            if out and Path(out).exists():
                raise LabctlError(f"{out}: already exists; choose another campaign file")
        except LabctlError as exc:
            self.query_one("#error", Static).update(str(exc))
            return
        s = self.settings
        s.protocol, s.out = protocol, Path(out) if out else None
        s.backend = "hw" if self.query_one("#hw", RadioButton).value else "sim"
        auto = self.query_one("#auto", Checkbox).value and s.backend == "sim"
        s.auto_confirm_s = (s.auto_confirm_s or DEFAULT_AUTO_CONFIRM_S) if auto else None
        self.dismiss(s)


class OpenFileScreen(ModalScreen[str]):
    """Ask for a campaign file to browse."""

    DEFAULT_CSS = SETUP_CSS
    BINDINGS = [Binding("escape", "cancel", "cancel")]

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label("Open a campaign file (.h5)")
            yield Input(placeholder="campaign.h5", id="path")
            yield Static("", id="error")

    def on_input_submitted(self, event: Input.Submitted) -> None:
        path = Path(event.value.strip())
        if not path.is_file():
            self.query_one("#error", Static).update(f"{path}: no such file")
            return
        self.dismiss(str(path))

    def action_cancel(self) -> None:
        self.dismiss("")
