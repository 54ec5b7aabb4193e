"""The key footer: Textual's, rebuilt only when the keys it shows change.

Textual rebuilds its footer (every key widget, its styles and the screen's layout) whenever a screen's bindings
may have changed: at every focus change and every dialog opened or closed, most often to show the same keys. On
the monitor that was a fifth of the drawing while blows are judged.
"""

from __future__ import annotations

from textual.screen import Screen
from textual.widgets import Footer


class KeyFooter(Footer):
    """A Footer that compares the keys it would show (key, action, description, enabled, tooltip) with those it
    shows and is rebuilt only when they differ."""

    def __init__(self) -> None:
        super().__init__()
        self._shown: tuple[tuple[object, ...], ...] | None = None

    def bindings_changed(self, screen: Screen) -> None:
        if self.is_attached and screen is self.screen and screen.app.app_focus:
            keys = tuple((b.key, b.action, b.description, b.show, enabled, tooltip)
                         for _, b, enabled, tooltip in screen.active_bindings.values())
            if keys == self._shown:
                return
            self._shown = keys
        super().bindings_changed(screen)
