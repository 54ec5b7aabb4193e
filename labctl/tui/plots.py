"""Terminal plots (plotext): the impact's force pulse and response, the FRF with coherence, stiffness vs load.

Each widget keeps the data it shows (tests read it) and redraws from it; the data arrives from events only.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from textual_plotext import PlotextPlot

from labctl.tui import plotdata as pd

RUN_COLORS = ("cyan", "magenta", "yellow", "green", "blue", "white")
RUN_MARKERS = ("●", "■", "▲", "◆", "✚", "✖")  # repetitions differ in shape as well as colour
MODEL_COLORS = {"Tripp": "red", "Hertz": "red"}


class TracePlot(PlotextPlot):
    """A plot that is redrawn whole from its stored lines; ``lines`` maps a label to (x, y)."""

    def __init__(self, title: str, xlabel: str, ylabel: str, *, id: str | None = None) -> None:  # noqa: A002
        super().__init__(id=id)
        self.title_text, self.xlabel, self.ylabel = title, xlabel, ylabel
        self.lines: dict[str, tuple[list[float], list[float]]] = {}
        self.marks: list[tuple[float, str]] = []  # vertical lines (x, colour)
        self.log_y = False
        self.y_range: tuple[float, float] | None = None  # fixed y span (coherence: 0–1)
        self.x_range: tuple[float, float] | None = None  # fixed x span (FRF: 0–2000 Hz)
        self._drawn: tuple[tuple[object, ...], object] | None = None  # (what it was drawn for, the drawing)
        self._version = 0  # one more at every redraw: the drawing kept for an older one is stale
        self.redraw()

    def render(self):  # noqa: ANN201 - the plot as PlotextPlot draws it, drawn again only when it would differ
        """Textual asks again at every screen switch (each dialog opening or closing) and plotext's build and the
        ANSI parse are the costliest part of a redraw: the drawing is kept until the lines, size or theme change."""
        key = (self._version, self.size.width, self.size.height, self.app.theme)
        if self._drawn is None or self._drawn[0] != key:
            self._drawn = (key, super().render())
        return self._drawn[1]

    def set_lines(self, lines: dict[str, tuple[Sequence[float], Sequence[float]]], title: str | None = None,
                  marks: list[tuple[float, str]] | None = None) -> None:
        """Replace the lines (with ``log_y`` the y values are drawn on a log axis: kept as log10, >0 only)."""
        if self.log_y:
            lines = {k: (np.asarray(x, dtype=float)[np.asarray(y, dtype=float) > 0],
                         np.log10(np.asarray(y, dtype=float)[np.asarray(y, dtype=float) > 0]))
                     for k, (x, y) in lines.items()}
        self.lines = {k: pd.finite_pairs(x, y) for k, (x, y) in lines.items()}
        self.lines = {k: v for k, v in self.lines.items() if v[0]}
        self.marks = [(x, c) for x, c in (marks or []) if math.isfinite(x)]
        if title is not None:
            self.title_text = title
        self.redraw()

    def point_count(self) -> int:
        return sum(len(x) for x, _ in self.lines.values())

    def redraw(self) -> None:
        plt = self.plt
        plt.clear_figure()
        plt.title(self.title_text)
        plt.xlabel(self.xlabel)
        plt.ylabel(self.ylabel)
        for i, (label, (x, y)) in enumerate(self.lines.items()):
            self.draw_line(label, x, y, i)
        for x, color in self.marks:
            plt.vline(x, color)
        self._axes()
        self._version += 1
        self.refresh()

    def _axes(self) -> None:
        """Limits and 1-2-5 ticks on the linear axes (plotext's own ticks fall on odd values)."""
        xs = [v for x, _ in self.lines.values() for v in x]
        ys = [v for _, y in self.lines.values() for v in y]
        if not xs:
            return
        x_lo, x_hi = self.x_range or pd.nice_range(min(xs), max(xs))
        self.plt.xlim(x_lo, x_hi)
        self.plt.xticks(*pd.nice_ticks(x_lo, x_hi))
        if self.log_y:  # the lines hold log10 values: ticks at whole decades, labelled with the value
            lo, hi = math.floor(min(ys)), math.ceil(max(ys))
            hi = hi if hi > lo else lo + 1
            every = max(1, math.ceil((hi - lo) / 5))
            decades = list(range(lo, hi + 1, every))
            self.plt.ylim(lo, hi)
            self.plt.yticks(decades, [f"{10.0 ** k:g}" for k in decades])
            return
        y_lo, y_hi = self.y_range or pd.nice_range(min(ys), max(ys))
        self.plt.ylim(y_lo, y_hi)
        self.plt.yticks(*pd.nice_ticks(y_lo, y_hi, 4))

    def draw_line(self, label: str, x: list[float], y: list[float], index: int) -> None:
        self.plt.plot(x, y, label=label if len(self.lines) > 1 else None,
                      color=RUN_COLORS[index % len(RUN_COLORS)], marker="braille")


class ImpactPlots:
    """The latest impact: force pulse around its peak and the vertical accelerations' first 100 ms."""

    def __init__(self, force: TracePlot, accel: TracePlot) -> None:
        self.force, self.accel = force, accel

    def show(self, force_n: np.ndarray, accel_m_per_s2: np.ndarray, channels: Sequence[str],
             sample_rate_hz: float, title: str) -> None:
        t, f = pd.pulse_window(force_n, sample_rate_hz)
        self.force.set_lines({"force": (t, f)}, title=title)
        accel = np.atleast_2d(np.asarray(accel_m_per_s2, dtype=float))
        lines = {}
        for i in pd.vertical_channels(channels)[:4]:
            lines[channels[i] if i < len(channels) else f"ch{i}"] = pd.response_window(accel[i], sample_rate_hz)
        self.accel.set_lines(lines)


class FrfPlots:
    """|H1| of the vertical channels (log scale) and their coherence, with the identified modes marked."""

    def __init__(self, magnitude: TracePlot, coherence: TracePlot) -> None:
        self.magnitude, self.coherence = magnitude, coherence
        self.magnitude.log_y = True
        self.magnitude.ylabel = "|H1| [(m/s²)/N]"
        self.coherence.ylabel = "coherence"
        self.coherence.y_range = (0.0, 1.0)  # never auto-scaled: a dip from 1 to 0.9 must look small
        self.magnitude.x_range = self.coherence.x_range = (0.0, pd.FRF_SPAN_HZ)

    def show(self, frequencies_hz: np.ndarray, h1_magnitude: np.ndarray, coherence: np.ndarray,
             channels: Sequence[str], bounce_hz: float, tilt_hz: Sequence[float], title: str) -> None:
        f_max = pd.FRF_SPAN_HZ  # the same span every step
        h1, coh = np.atleast_2d(np.abs(h1_magnitude)), np.atleast_2d(coherence)
        idx = pd.vertical_channels(channels)[:4]
        name = [channels[i] if i < len(channels) else f"ch{i}" for i in idx]
        mags = {n: pd.frf_band(frequencies_hz, h1[i], f_max) for n, i in zip(name, idx, strict=True)}
        cohs = {n: pd.frf_band(frequencies_hz, coh[i], f_max) for n, i in zip(name, idx, strict=True)}
        marks = [(bounce_hz, "red")] + [(t, "orange") for t in tilt_hz]
        self.magnitude.set_lines(mags, title=title, marks=marks)
        self.coherence.set_lines(cohs, marks=marks)


class StiffnessPlot(TracePlot):
    """Measured roller stiffness per run (points) against the reference models (lines), in N/µm."""

    def __init__(self, *, id: str | None = None) -> None:  # noqa: A002
        self.models: dict[str, tuple[list[float], list[float]]] = {}
        self.runs: dict[str, tuple[list[float], list[float]]] = {}
        super().__init__("", "load per roller [N]", "k [N/µm]", id=id)

    def set_models(self, models: dict[str, tuple[Sequence[float], Sequence[float]]]) -> None:
        """Reference curves as (load N, stiffness N/m)."""
        self.models = {k: pd.finite_pairs(x, np.asarray(y, dtype=float) / pd.N_PER_UM) for k, (x, y) in models.items()}
        self.models = {k: v for k, v in self.models.items() if v[0]}
        self.redraw()

    def set_runs(self, runs: dict[str, tuple[Sequence[float], Sequence[float]]]) -> None:
        """Measured points per run label as (load N, stiffness N/m)."""
        self.runs = {k: pd.finite_pairs(x, np.asarray(y, dtype=float) / pd.N_PER_UM) for k, (x, y) in runs.items()}
        self.redraw()

    def point_count(self) -> int:
        return sum(len(x) for x, _ in self.runs.values())

    def redraw(self) -> None:
        self.lines = {**getattr(self, "models", {}), **getattr(self, "runs", {})}
        super().redraw()

    def draw_line(self, label: str, x: list[float], y: list[float], index: int) -> None:
        if label in self.models:
            color = MODEL_COLORS.get(label, "green" if "Eq. 5" in label else "blue")
            self.plt.plot(x, y, label=label, color=color, marker="braille")
        else:
            run_index = list(self.runs).index(label)
            self.plt.scatter(x, y, label=label, color=RUN_COLORS[run_index % len(RUN_COLORS)],
                             marker=RUN_MARKERS[run_index % len(RUN_MARKERS)])
