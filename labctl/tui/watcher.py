"""The watch screen: a campaign another process is running, followed read-only from its file, once a second.

It shows the file's status, the counts, every stored step (load, bounce, stiffness, what happened) and the
run log as it grows, until the campaign ends; ``o`` then browses the file.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

from rich.markup import escape
from textual import work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.css.query import NoMatches
from textual.screen import Screen
from textual.widgets import DataTable, RichLog, Static

from labctl.errors import InputError
from labctl.tui.dialogs import show_text
from labctl.tui.footer import KeyFooter
from labctl.tui.plots import StiffnessPlot
from labctl.tui.watch import Snapshot, read_snapshot

WATCH_CSS = """
WatchScreen #w-header { height: auto; max-height: 4; background: $primary-background; padding: 0 1; }
WatchScreen #w-header.-done { background: $success 30%; }
WatchScreen #w-header.-failed { background: $error 40%; }
WatchScreen #w-main { height: 1fr; }
WatchScreen.-narrow #w-main { layout: vertical; }
WatchScreen.-narrow #w-steps { width: 100%; height: 40%; }
WatchScreen #w-steps { width: 1fr; height: 1fr; border: round $primary; }
WatchScreen #w-side { width: 1fr; }
WatchScreen #w-stiffness { height: 1fr; border: round $primary; }
WatchScreen #w-log { height: 1fr; border: round $primary; }
WatchScreen.-narrow #w-side { width: 100%; }
WatchScreen.-narrow #w-stiffness, WatchScreen.-short #w-stiffness { display: none; }
"""


class WatchScreen(Screen):
    """Follows ``path`` (which may not exist yet) until its status is final."""

    DEFAULT_CSS = WATCH_CSS
    BINDINGS = [Binding("o", "browse", "browse file"), Binding("q", "app.quit", "quit")]
    HORIZONTAL_BREAKPOINTS = [(0, "-narrow"), (140, "-wide")]  # narrower: the table above the log, rows whole
    VERTICAL_BREAKPOINTS = [(0, "-short"), (36, "-tall")]

    def __init__(self, path: Path, interval_s: float = 1.0) -> None:
        super().__init__()
        self.path, self.interval_s = path, interval_s
        self.snapshot: Snapshot | None = None
        self.problem = ""
        self.read_at: float | None = None
        self._seen_steps: set[tuple[int, int, int, bool]] = set()
        self._log_lines = 0

    def compose(self) -> ComposeResult:
        yield Static("", id="w-header")
        with Horizontal(id="w-main"):
            yield DataTable(id="w-steps", cursor_type="row", zebra_stripes=True)
            with Vertical(id="w-side"):
                yield StiffnessPlot(id="w-stiffness")
                yield RichLog(id="w-log", markup=True, wrap=True, min_width=20, max_lines=2000)  # wraps at its width
        yield KeyFooter()

    def on_mount(self) -> None:
        table = self.query_one("#w-steps", DataTable)
        table.add_columns("run", "step", "load N", "hits", "bounce Hz", "k N/µm", "what happened")
        self.query_one("#w-steps").border_title = "steps in the file"
        self.query_one("#w-log").border_title = "run log and events"
        self.query_one("#w-stiffness").border_title = "stiffness vs load"
        self.show()
        self.poll()
        self.set_interval(self.interval_s, self.poll)

    @work(thread=True, exclusive=True, group="watch")
    def poll(self) -> None:
        """Read the file in a worker thread (never the UI's) and hand the snapshot over."""
        if self.snapshot is not None and self.snapshot.finished:
            return
        try:
            snap, problem = read_snapshot(self.path), ""
        except InputError as exc:
            snap, problem = None, str(exc)
        self.app.call_from_thread(self.update_from, snap, problem)

    def update_from(self, snap: Snapshot | None, problem: str) -> None:
        self.read_at = time.monotonic()
        self.problem = problem
        try:
            if snap is not None:
                self._apply(snap)
            self.show()
        except NoMatches:
            return  # the screen's widgets are gone (it is closing): a read that ended after them is dropped

    def _apply(self, snap: Snapshot) -> None:
        log = self.query_one("#w-log", RichLog)
        table = self.query_one("#w-steps", DataTable)
        for line in snap.log[self._log_lines:]:
            log.write(escape(line))
        self._log_lines = len(snap.log)
        table.clear()
        for s in snap.steps:
            k = "--" if math.isnan(s.stiffness_n_per_m) else f"{s.stiffness_n_per_m * 1e-6:.2f}"
            bounce = "--" if math.isnan(s.bounce_hz) else f"{s.bounce_hz:.2f}"
            table.add_row(str(s.run), str(s.step), f"{s.load_n:.1f}", f"{s.accepted}/{s.impacts}", bounce, k,
                          " · ".join(s.flags) or ("" if s.complete else
                                                  "unfinished" if snap.finished else "in progress"))
            key = (s.series, s.run, s.step, s.complete)
            if s.complete and key not in self._seen_steps:
                self._seen_steps.add(key)
                log.write(f"[cyan]step {s.step} (run {s.run}) stored: {s.load_n:.1f} N, bounce {bounce} Hz, "
                          f"k {k} N/µm[/]")
                for note in s.notes:
                    log.write(f"[yellow]  {escape(note)}[/]")
        if snap.steps:
            table.move_cursor(row=table.row_count - 1)
        runs: dict[str, tuple[list[float], list[float]]] = {}
        for s in snap.steps:
            if s.identified:
                xs, ks = runs.setdefault(f"run {s.run}" if s.series == 1 else f"series {s.series} run {s.run}",
                                         ([], []))
                xs.append(s.load_n)
                ks.append(s.stiffness_n_per_m)
        self.query_one("#w-stiffness", StiffnessPlot).set_runs({k: (v[0], v[1]) for k, v in runs.items()})
        if snap.finished and not (self.snapshot is not None and self.snapshot.finished):
            log.write(f"[b]campaign {escape(snap.status)}: o browses the file, q quits[/b]")
        self.snapshot = snap

    def header_text(self) -> str:
        """The state of the file as last read; says when it could not be read (and that it keeps trying)."""
        snap = self.snapshot
        head = f"WATCHING (read-only) {self.path}"
        if snap is None:
            retry = f" · trying again every {self.interval_s:g} s" if self.problem else ""
            return escape(f"{head}\n{self.problem or 'reading…'}{retry}")
        state = snap.status.upper() or "RUNNING"
        last = snap.steps[-1] if snap.steps else None
        where = f"run {last.run} · step {last.step}" if last else "no step yet"
        line = (f"{snap.protocol} on {snap.backend} · {where} · {len(snap.steps)} steps · "
                f"{snap.accepted}/{snap.impacts} impacts accepted")
        stale = f"\nlast read failed: {self.problem}" if self.problem else ""
        return f"[b]{escape(state)}[/b]  {escape(head)}\n{escape(line)}{escape(stale)}"

    def show(self) -> None:
        header = self.query_one("#w-header", Static)
        show_text(header, self.header_text())
        status = self.snapshot.status if self.snapshot else ""
        header.set_class(status == "complete", "-done")
        header.set_class(status in ("failed", "aborted", "interlock"), "-failed")

    def action_browse(self) -> None:
        if self.snapshot is None or not self.snapshot.finished:
            self.notify("the campaign is still running: browse it once it has ended", severity="warning")
            return
        from labctl.tui.browser import BrowserScreen

        self.app.push_screen(BrowserScreen(self.path, locking=False))
