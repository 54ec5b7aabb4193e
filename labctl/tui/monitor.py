"""The live screen at the rig: progress header, latest impact, FRF, modes, stiffness curve and the log.

Every widget here changes only in ``apply``, which the app calls in its own thread for each engine event.
"""

from __future__ import annotations

import math
import time

from rich.markup import escape
from textual.app import ComposeResult
from textual.containers import Horizontal, Vertical
from textual.screen import Screen
from textual.widgets import DataTable, RichLog, Static

from labctl import events as ev
from labctl.protocol import Protocol
from labctl.tui import plotdata as pd
from labctl.tui.dialogs import ConfirmDialog, PromptDialog, ReviewDialog, prompt_title, show_text
from labctl.tui.footer import KeyFooter
from labctl.tui.plots import FrfPlots, ImpactPlots, StiffnessPlot, TracePlot
from labctl.tui.state import CampaignState, StepRow, reason_text, row_cells, tilt_text

MONITOR_CSS = """
#header { height: auto; max-height: 4; background: $primary-background; color: $text; padding: 0 1; }
#header.-paused { background: $warning 40%; }
#header.-done { background: $success 30%; }
#header.-failed { background: $error 40%; }
#top, #bottom { height: 1fr; }
.panel { border: round $primary; width: 1fr; height: 1fr; }
.panel.-rejected { border: heavy $error; }
#impact-panel, #frf-panel { width: 1fr; }
#modes { height: auto; padding: 0 1; color: $accent; text-style: bold; }
#steps { height: 1fr; min-height: 3; }
#log { height: 1fr; min-height: 3; }
#side { width: 1fr; }
MonitorScreen.-short #top { height: 2fr; }
MonitorScreen.-short #bottom { height: 3fr; }
MonitorScreen.-short #accel-plot, MonitorScreen.-short #coh-plot { display: none; }
MonitorScreen.-narrow #accel-plot, MonitorScreen.-narrow #coh-plot { display: none; }
"""

STATUS_WORDS = {"idle": "ready (s to start)", "running": "RUNNING", "paused": "PAUSED (p to resume)",
                "stopping": "stopping after the current impact…"}

HANDLERS: dict[type[ev.Event], str] = {
    ev.CampaignStarted: "_started",
    ev.RunStarted: "_run_started",
    ev.StepStarted: "_step_started",
    ev.ImpactAcquired: "_impact",
    ev.StepProcessed: "_step_processed",
    ev.StepFailed: "_step_failed",
    ev.RunProcessed: "_run_processed",
    ev.OperatorPrompted: "_prompted",
    ev.Paused: "_paused",
    ev.Resumed: "_resumed",
    ev.Suspended: "_suspended",
    ev.Notice: "_notice",
    ev.CampaignFinished: "_finished",
    ev.ImpactRejected: "_impact",
}


def fit_title(variants: list[str], width: int) -> str:
    """The longest of ``variants`` (longest first) that fits a border of ``width`` columns whole, so a title
    is shortened by dropping what matters least, never cut mid-word; the last variant when none fits."""
    room = width - 6  # corners, the title's padding
    return next((v for v in variants if len(v) <= room), variants[-1])


def run_label(series: int, run: int, series_total: int) -> str:
    return f"series {series} run {run}" if series_total > 1 else f"run {run}"


class MonitorScreen(Screen):
    """The run being acquired; the app forwards engine events to ``apply``."""

    DEFAULT_CSS = MONITOR_CSS
    HORIZONTAL_BREAKPOINTS = [(0, "-narrow"), (120, "-wide")]
    VERTICAL_BREAKPOINTS = [(0, "-short"), (36, "-tall")]

    def __init__(self, protocol: Protocol | None = None) -> None:
        super().__init__()
        self.protocol = protocol
        self.state = CampaignState()
        self.series_shown = 0

    def compose(self) -> ComposeResult:
        yield Static("", id="header")
        with Horizontal(id="top"):
            with Vertical(id="impact-panel", classes="panel"):
                yield TracePlot("", "t [ms] from peak", "F [N]", id="force-plot")
                yield TracePlot("", "t [ms]", "a [m/s²]", id="accel-plot")
            with Vertical(id="frf-panel", classes="panel"):
                yield TracePlot("", "f [Hz]", "|H1| [(m/s²)/N]", id="frf-plot")
                yield TracePlot("", "f [Hz]", "coherence", id="coh-plot")
        with Horizontal(id="bottom"):
            yield StiffnessPlot(id="stiffness")
            with Vertical(id="side", classes="panel"):
                yield Static(self.state.modes_text(), id="modes")
                yield DataTable(id="steps", cursor_type="row", zebra_stripes=True)
                yield RichLog(id="log", markup=True, wrap=True, min_width=20, max_lines=2000)
        yield KeyFooter()

    def on_mount(self) -> None:
        self.query_one("#impact-panel").border_title = "last impact: waiting"
        self.query_one("#frf-panel").border_title = "FRF: after the first step"
        self.query_one("#side").border_title = "modes and log"
        self.query_one("#stiffness").add_class("panel")
        self.query_one("#stiffness").border_title = "stiffness vs load"
        table = self.query_one("#steps", DataTable)
        table.add_columns("run", "step", "load N", "bounce Hz", "tilt Hz", "k N/µm", "coh")
        self.impact = ImpactPlots(self.query_one("#force-plot", TracePlot), self.query_one("#accel-plot", TracePlot))
        self.frf = FrfPlots(self.query_one("#frf-plot", TracePlot), self.query_one("#coh-plot", TracePlot))
        self.set_interval(1.0, self.refresh_header)
        self.app.screen_change_signal.subscribe(self, lambda _screen: self.call_later(self.refresh_header))
        self.refresh_header()

    # --- header and log -------------------------------------------------------------------------------------
    def asked(self) -> tuple[str, bool]:
        """What the open dialog asks the technician ("" when none), and whether it stops the work (every dialog
        but the per-hit gate, which is part of taking a blow): the header says it, the ETA stands still."""
        for screen in reversed(self.app.screen_stack):
            if isinstance(screen, ConfirmDialog):
                return screen.asks, True
            if isinstance(screen, ReviewDialog) and not screen.closed:
                return "JUDGE THE BLOW: y accept · r reject (nothing armed)", False
            if isinstance(screen, PromptDialog) and not screen.closed:
                return (f"WAITING FOR YOU: {prompt_title(screen.request.action, screen.hint)} "
                        "(nothing armed)"), True
        return "", False

    def refresh_header(self) -> None:
        s = self.state
        title = f"labctl · {s.protocol or (self.protocol.name if self.protocol else 'no protocol')}"
        if s.backend:
            title += f" · {s.backend} → {s.path}"
        if self.is_mounted:
            s.hold(*self.asked())
        status = STATUS_WORDS.get(s.status, s.status.upper())
        if s.waiting and s.status == "running":
            status = "WAITING FOR THE OPERATOR"
        header = self.query_one("#header", Static)
        prompt = s.prompt_text()
        show_text(header, f"[b]{escape(status)}[/b]  {escape(title)}\n{escape(s.counters_text())}"
                  + (f"\n[b]{escape(prompt)}[/b]" if prompt else ""))
        header.set_class(s.status == "paused" or bool(s.waiting and s.status == "running"), "-paused")
        header.set_class(s.status == "complete", "-done")
        header.set_class(s.status in ("failed", "aborted", "interlock"), "-failed")

    def log_line(self, text: str, style: str = "") -> None:
        stamp = time.strftime("%H:%M:%S")
        body = escape(text)
        self.query_one("#log", RichLog).write(f"[dim]{stamp}[/dim] " + (f"[{style}]{body}[/]" if style else body))

    def set_status(self, status: str) -> None:
        self.state.status = status
        self.refresh_header()

    # --- events ---------------------------------------------------------------------------------------------
    def apply(self, event: ev.Event) -> None:
        """Fold one engine event into the state and update the widgets it concerns."""
        self.state.apply(event)
        handler = HANDLERS.get(type(event))
        if handler is not None:
            getattr(self, handler)(event)
        self.refresh_header()

    def _started(self, e: ev.CampaignStarted) -> None:
        verb = "resuming" if e.resumed else "starting"
        self.log_line(f"{verb} {e.protocol} on {e.backend or 'sim'} → {e.path}", "bold")

    def _run_started(self, e: ev.RunStarted) -> None:
        self.log_line(f"{run_label(e.position.series, e.position.run, self.state.series_total)}: {e.specimen}", "bold")
        if e.position.series != self.series_shown:
            self.series_shown = e.position.series
            self._show_models(e.position.series)
            self._show_runs()

    def _step_started(self, e: ev.StepStarted) -> None:
        self.log_line(f"step {e.position.step}/{e.steps_total}: knobs at {e.knob_angle_deg:g}°, "
                      f"expecting about {e.expected_load_n:.0f} N per roller")

    def _impact(self, e: ev.ImpactAcquired) -> None:
        p, rejected = e.position, isinstance(e, ev.ImpactRejected)
        head = f"step {p.step} impact {e.attempt}"
        width = self.query_one("#impact-panel").size.width or 60
        gate = getattr(getattr(self.app, "operator", None), "reviews_hits", False)
        if rejected:  # with the gate the technician decides; without it the checks' rejection stands
            word = "FLAGGED" if gate else "REJECTED"
            title = fit_title([f"{head} {word}: {reason_text(e.reasons)}", f"{head} {word}"], width)
            self.log_line(f"{head} flagged by the checks ({reason_text(e.reasons)}): "
                          + ("judge it" if gate else "not used, hit again"), "bold red")
        else:
            title = fit_title([f"{head} ok · {e.peak_force_n:.0f} N · {e.pulse_width_s * 1e3:.2f} ms",
                               f"{head} ok · {e.peak_force_n:.0f} N"], width)
            self.log_line(f"{head}: {e.peak_force_n:.0f} N, pulse {e.pulse_width_s * 1e3:.2f} ms", "green")
        panel = self.query_one("#impact-panel")
        panel.set_class(rejected, "-rejected")
        panel.border_title = title
        panel.border_subtitle = fit_title([self.state.range_text(n) for n in (6, 4, 3, 2, 1)], width)
        full = [name for name, use in e.range_use.items() if use >= 1.0]
        clipped = sorted({r.partition(":")[2] for r in e.reasons if r.startswith("clipped:")} | set(full))
        if clipped:
            self.log_line(f"OVERLOAD on {', '.join(clipped)}: hit softer or raise that channel's range", "bold red")
        self.impact.show(e.force_n, e.accel_m_per_s2, e.channels, e.sample_rate_hz, "")

    def _step_processed(self, e: ev.StepProcessed) -> None:
        p = e.position
        show_text(self.query_one("#modes", Static), self.state.modes_text())
        tilt = tilt_text(e.tilt_hz)
        table = self.query_one("#steps", DataTable)
        table.add_row(*row_cells(self.state.steps[-1]))
        table.move_cursor(row=table.row_count - 1)
        self.log_line(f"load {e.load_n:.1f} N · " + self.state.step_summary(e), "cyan")
        self.frf.show(e.frequencies_hz, e.h1_magnitude, e.coherence, e.channels, e.bounce_hz, e.tilt_hz, "")
        panel = self.query_one("#frf-panel")
        panel.border_title = fit_title([
            f"FRF step {p.step}: bounce {e.bounce_hz:.2f} Hz (red), tilt {tilt} Hz (orange)",
            f"step {p.step}: bounce {e.bounce_hz:.1f} (red) · tilt {tilt} Hz",
            f"step {p.step}: bounce {e.bounce_hz:.1f} Hz"],
            panel.size.width or 60)
        self._show_runs()

    def _step_failed(self, e: ev.StepFailed) -> None:
        self.log_line(f"step {e.position.step} could not be identified: {e.reason}", "bold red")

    def _run_processed(self, e: ev.RunProcessed) -> None:
        self.log_line(f"{run_label(e.position.series, e.position.run, self.state.series_total)}: "
                      f"{len(e.load_n)} points stored", "bold")
        if not self.query_one("#stiffness", StiffnessPlot).models and e.reference_n_per_m:
            refs = {pd.MODEL_LABELS.get(k, k): (e.load_n, v) for k, v in e.reference_n_per_m.items()}
            self.query_one("#stiffness", StiffnessPlot).set_models(refs)
        self._show_runs()

    def _prompted(self, e: ev.OperatorPrompted) -> None:
        self.log_line(f"operator: {e.message} → {e.answer}", "yellow")

    def _paused(self, e: ev.Paused) -> None:
        self.log_line("paused at a safe point (between impacts)", "bold yellow")

    def _resumed(self, e: ev.Resumed) -> None:
        self.log_line(f"resumed: {e.reason.replace('_', ' ')}" if e.reason else "resumed", "bold")

    def _suspended(self, e: ev.Suspended) -> None:
        self.log_line(e.reason, "bold yellow")

    def _notice(self, e: ev.Notice) -> None:
        self.log_line(e.message, {"warning": "yellow", "error": "bold red"}.get(e.level, ""))

    def _finished(self, e: ev.CampaignFinished) -> None:
        style = "bold green" if e.status == "complete" else "bold red"
        self.log_line(f"campaign {e.status}: {e.path}" + (f" ({e.message})" if e.message else ""), style)
        for line in self.state.end_summary(pd.MODEL_LABELS):
            self.log_line(line, "bold")
        if e.status == "complete":
            self.log_line("o: browse this file · q: quit")

    def preload(self, path: str) -> None:
        """Show what an interrupted campaign already holds before the engine continues it: its identified steps,
        and its unused blows in the campaign's counts, so the end summary covers the whole campaign."""
        from labctl.storage import CampaignReader
        from labctl.tui.state import blow_reason

        with CampaignReader(path) as reader:
            for series in reader.series_indices():
                for run in reader.runs(series):
                    for step in run.steps:
                        r = step.result
                        if r is None:  # unfinished: the engine finishes it and reports all its blows
                            continue
                        if not r.identified:
                            self.state.steps_failed += 1
                            continue
                        stored = {i.attempt: i for i in step.impacts}
                        for outcome in r.impacts:
                            if not outcome.used:
                                info = stored.get(outcome.attempt)
                                why = info.reasons if info is not None and not info.accepted else outcome.reasons
                                key = blow_reason(tuple(why))
                                self.state.rejected[key] = self.state.rejected.get(key, 0) + 1
                        tilt = tuple(float(t) for t in r.tilt_hz)[:2]
                        row = StepRow(series, run.run, step.step, step.load_n, r.bounce_hz,
                                      (tilt + (math.nan, math.nan))[:2], r.roller_stiffness_n_per_m,
                                      r.coherence_at_bounce)
                        self.state.add_row(row)
                        self.query_one("#steps", DataTable).add_row(*row_cells(row))
        unused = sum(self.state.rejected.values())
        self.log_line(f"{path}: {len(self.state.steps)} identified steps already in the file"
                      + (f", {unused} blows in them not used" if unused else ""))

    # --- stiffness plot -------------------------------------------------------------------------------------
    def _show_models(self, series: int) -> None:
        if self.protocol is None or not 1 <= series <= len(self.protocol.specimens):
            return
        spec = self.protocol.specimens[series - 1]
        models = pd.model_curves(spec.case(), spec.kind, max(spec.max_load_n / 20, 1.0), spec.max_load_n * 1.05)
        self.query_one("#stiffness", StiffnessPlot).set_models(models)
        self.query_one("#stiffness").border_title = f"stiffness vs load · {spec.label}"

    def _show_runs(self) -> None:
        runs = {run_label(s, r, self.state.series_total): curve
                for (s, r), curve in sorted(self.state.curves.items()) if s == self.series_shown}
        self.query_one("#stiffness", StiffnessPlot).set_runs(runs)
