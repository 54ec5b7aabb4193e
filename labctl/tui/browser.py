"""Browse a campaign file: series, runs, steps and impacts in a tree; the selection's curve, FRF or traces."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.screen import Screen
from textual.widgets import Static, Tree

from labctl.errors import LabctlError
from labctl.protocol import parse_protocol
from labctl.report.notes import check_words, step_events
from labctl.storage import CampaignReader, ImpactInfo, StepInfo
from labctl.storage.records import OPERATOR
from labctl.tui import plotdata as pd
from labctl.tui.footer import KeyFooter
from labctl.tui.plots import FrfPlots, ImpactPlots, StiffnessPlot, TracePlot
from labctl.tui.state import reason_text, tilt_text

BROWSER_CSS = """
BrowserScreen #title { height: 1; background: $primary-background; padding: 0 1; }
BrowserScreen #tree { width: 45%; min-width: 36; border: round $primary; }
BrowserScreen.-narrow #b-main { layout: vertical; }
BrowserScreen.-narrow #tree { width: 100%; height: 45%; }
BrowserScreen.-narrow #b-frf, BrowserScreen.-short #b-traces { display: none; }
BrowserScreen #detail { height: auto; max-height: 10; padding: 0 1; }
BrowserScreen .row { height: 1fr; }
BrowserScreen .panel { border: round $primary; width: 1fr; height: 1fr; }
"""


def step_label(step: StepInfo) -> str:
    """One line per step: load, bounce frequency, stiffness and accepted impacts."""
    r = step.result
    text = f"step {step.step}: {step.load_n:.1f} N"
    if r is not None and r.identified:
        text += f" · {r.bounce_hz:.2f} Hz · k {r.roller_stiffness_n_per_m * 1e-6:.2f} N/µm"
    elif r is not None or step.complete:
        text += " · not identified"
    elif not step.complete:
        text += " · unfinished"
    text += f" · {step.accepted_count}/{len(step.impacts)} hits"
    return text + "".join(f" · {f}" for f in step_events(step).flags() if "warning" not in f)


def impact_label(imp: ImpactInfo, reason: bool = False) -> str:
    """One line per impact: its peak force and the verdict, and who gave it; an override says so (with
    ``reason``: and why, as the detail line shows it)."""
    v = imp.verdict
    if v.source == OPERATOR and v.accepted != imp.checks.accepted:
        said = "clean" if imp.checks.accepted else f"flagged {check_words(imp.checks.reasons)}"
        verdict = f"{'ACCEPTED' if v.accepted else 'REJECTED'} by the operator ({said})" + (
            f": {v.reason or 'no reason given'}" if reason else "")
    elif v.accepted:
        verdict = "ok"
    else:
        verdict = f"rejected: {reason_text(imp.reasons)}" + (f" ({v.reason})" if v.source == OPERATOR and v.reason
                                                               else "")
    return f"impact {imp.attempt}: {imp.peak_force_n:.0f} N · {verdict}"


class BrowserScreen(Screen):
    """A read-only view of a campaign file (opened at construction; a bad file raises InputError)."""

    DEFAULT_CSS = BROWSER_CSS
    BINDINGS = [Binding("escape,b", "back", "back")]
    HORIZONTAL_BREAKPOINTS = [(0, "-narrow"), (140, "-wide")]  # narrower: the tree above, its labels whole
    VERTICAL_BREAKPOINTS = [(0, "-short"), (36, "-tall")]

    def __init__(self, path: Path, locking: bool | None = None) -> None:
        super().__init__()
        self.reader = CampaignReader(path, locking=locking)  # False: a file just watched, opened as the watcher did
        self.protocol = None
        try:
            text = self.reader.config_text("protocol.toml")
            self.protocol = parse_protocol(text, f"{path}:protocol.toml") if text else None
        except LabctlError:
            self.protocol = None

    def compose(self) -> ComposeResult:
        a = self.reader.attrs
        yield Static(f"{self.reader.path} · {a.get('protocol_name', '?')} on {a.get('backend', '?')} · "
                     f"status {a.get('status', '?')} {a.get('status_message', '')}", id="title", markup=False)
        with Horizontal(id="b-main"):
            yield Tree(self.reader.path.name, id="tree")
            with Vertical():
                yield Static("select a series, run, step or impact", id="detail", markup=False)
                with Horizontal(classes="row"):
                    yield StiffnessPlot(id="b-stiffness")
                    with Vertical(classes="panel", id="b-frf"):
                        yield TracePlot("FRF", "f [Hz]", "|H1| [(m/s²)/N]", id="b-frf-plot")
                        yield TracePlot("", "f [Hz]", "coherence", id="b-coh-plot")
                with Horizontal(classes="row", id="b-traces"):
                    yield TracePlot("impact force", "t [ms] from peak", "F [N]", id="b-force")
                    yield TracePlot("response", "t [ms]", "a [m/s²]", id="b-accel")
        yield KeyFooter()

    def on_mount(self) -> None:
        self.frf = FrfPlots(self.query_one("#b-frf-plot", TracePlot), self.query_one("#b-coh-plot", TracePlot))
        self.impact = ImpactPlots(self.query_one("#b-force", TracePlot), self.query_one("#b-accel", TracePlot))
        tree = self.query_one("#tree", Tree)
        tree.root.expand()
        for series in self.reader.series_indices():
            spec = self.reader.specimen(series)
            node = tree.root.add(f"series {series}: {spec.label or '?'} (rails Ra {spec.rail_ra_m * 1e6:g} µm)",
                                 data=("series", series), expand=True)
            for run in self.reader.runs(series):
                rnode = node.add(f"run {run.run} · {'complete' if run.complete else 'unfinished'} · "
                                 f"{len(run.steps)} steps", data=("run", series, run.run), expand=True)
                for step in run.steps:
                    snode = rnode.add(step_label(step), data=("step", series, run.run, step.step))
                    for imp in step.impacts:
                        snode.add_leaf(impact_label(imp), data=("impact", series, run.run, step.step, imp.attempt))
        tree.focus()
        if self.reader.series_indices():
            self.show_series(self.reader.series_indices()[0])

    def on_unmount(self) -> None:
        self.reader.close()

    def action_back(self) -> None:
        self.app.pop_screen()

    def on_tree_node_highlighted(self, event: Tree.NodeHighlighted) -> None:
        data = event.node.data
        if not data:
            return
        kind, series, *rest = data
        self.show_series(series)
        if kind == "step" or kind == "impact":
            self.show_step(series, rest[0], rest[1], rest[2] if kind == "impact" else None)

    # --- views ----------------------------------------------------------------------------------------------
    def show_series(self, series: int) -> None:
        plot = self.query_one("#b-stiffness", StiffnessPlot)
        runs = {}
        for run in self.reader.runs(series):
            curve = self.reader.curve(series, run.run)
            if curve is None:  # unfinished run: its identified steps so far
                pts = [(s.load_n, s.result.roller_stiffness_n_per_m) for s in run.steps
                       if s.result is not None and s.result.identified]
                runs[f"run {run.run}"] = (np.array([p[0] for p in pts]), np.array([p[1] for p in pts]))
            else:
                runs[f"run {run.run}"] = (curve.load_n, curve.stiffness_n_per_m)
        plot.set_runs(runs)
        if self.protocol is not None and series <= len(self.protocol.specimens):
            spec = self.protocol.specimens[series - 1]
            plot.set_models(pd.model_curves(spec.case(), spec.kind, max(spec.max_load_n / 20, 1.0),
                                            spec.max_load_n * 1.05))

    def show_step(self, series: int, run: int, step: int, attempt: int | None) -> None:
        info = next(s for r in self.reader.runs(series) if r.run == run for s in r.steps if s.step == step)
        r = info.result
        lines = [step_label(info)]
        if r is not None and r.identified:
            lines.append(f"bounce {r.bounce_hz:.2f} Hz · tilt {tilt_text(list(r.tilt_hz))} Hz · "
                         f"damping {r.bounce_damping_ratio:.4f} · coherence {r.coherence_at_bounce:.3f}")
        happened = step_events(info)
        lines.append(f"load {happened.load_before_n:.1f} N before the blows, "
                     + (f"{happened.load_after_n:.1f} N after" if math.isfinite(happened.load_after_n)
                        else "not read after"))
        lines += happened.notes()
        if attempt is not None:
            imp = next((i for i in info.impacts if i.attempt == attempt), None)
            if imp is not None:
                lines.append(impact_label(imp, reason=True))
        self.query_one("#detail", Static).update("\n".join(lines))
        frf = self.reader.step_frf(series, run, step)
        if frf is not None and r is not None:
            self.frf.show(frf[0], np.abs(frf[1]), frf[2], tuple(r.channels), r.bounce_hz,
                          [float(t) for t in r.tilt_hz], f"step {step} FRF")
        data = self.reader.impact_arrays(series, run, step)
        if not data.attempts:
            return
        i = data.attempts.index(attempt) if attempt in data.attempts else 0
        verdict = "ok" if data.accepted[i] else "rejected"
        self.impact.show(data.force_n[i], data.accel_m_per_s2[i], data.channels, data.sample_rate_hz,
                         f"impact {data.attempts[i]} ({verdict})")
