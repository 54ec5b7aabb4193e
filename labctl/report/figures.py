"""The paper's figures from a campaign (matplotlib, no screen): Fig. 8, Figs. 12–13, Fig. 7, frequency vs load.

Each function returns a Figure; :func:`make_figures` names them and :func:`save` writes PNG and SVG.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from labctl.physics import FITS, EmpiricalFit, rig_modes
from labctl.physics.references import fit_for_rail, model_curve
from labctl.report.data import FrfStep, ReportData, SeriesData

MM = 1e-3
CURVE_POINTS = 80
FRF_MAX_HZ = 2000.0  # the paper's range of interest
FIT_BAND = 0.10  # most points lie within ±10 % of Eqs. 5/6
HERTZ_BAND = 0.05  # the ball verification's agreement


@dataclass
class Plot:
    name: str
    title: str
    figure: Figure


def _load_grid(series: SeriesData) -> np.ndarray:
    f = series.all_loads
    return np.geomspace(0.8 * f.min(), 1.1 * f.max(), CURVE_POINTS)


def _finish(ax: Axes, xlabel: str, ylabel: str, title: str, legend_size: int = 8, sci_y: bool = True) -> None:
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    if sci_y:
        ax.ticklabel_format(axis="y", style="sci", scilimits=(0, 0))
    ax.grid(alpha=0.3)
    ax.legend(fontsize=legend_size)


def load_stiffness(series: SeriesData) -> Figure:
    """Fig. 8: stiffness vs load per repetition, with the mean and the spread over the repetitions."""
    fig = Figure(figsize=(6.4, 4.4), layout="constrained")
    ax = fig.subplots()
    for i, r in enumerate(series.runs):
        ax.plot(r.load_n, r.stiffness_n_per_m, ls="none", marker="os^vD<>"[i % 7], ms=5, mfc="none",
                color=f"C{i % 10}", label=f"repetition {r.run}")
    stats = series.step_stats()
    f = np.array([s.load_n for s in stats])
    k = np.array([s.stiffness_n_per_m for s in stats])
    ax.fill_between(f, [s.k_min for s in stats], [s.k_max for s in stats], color="0.8", label="spread (min–max)")
    ax.plot(f, k, "k-", lw=1.2, label="mean")
    _finish(ax, "load per roller F [N]", "roller stiffness k [N/m]",
            f"{series.label}, rail Ra {series.case.rail_ra_m * 1e6:.3g} µm")
    return fig


def models(group: list[SeriesData], fit: str) -> Figure:
    """Figs. 12/13: measured means per contact length vs Tripp, Palmgren and the fit (Eq. 5 or 6) ±10 %."""
    fig = Figure(figsize=(6.8, 4.8), layout="constrained")
    ax = fig.subplots()
    coeff = FITS[fit]
    for i, s in enumerate(group):
        length = s.case.roller.contact_length_m
        stats = s.step_stats()
        f = np.array([st.load_n for st in stats])
        k = np.array([st.stiffness_n_per_m for st in stats])
        err = np.array([[st.stiffness_n_per_m - st.k_min, st.k_max - st.stiffness_n_per_m] for st in stats]).T
        color = f"C{i % 10}"
        ax.errorbar(f / length * MM, k / length * MM, yerr=err / length * MM, fmt="o", ms=4, color=color,
                    capsize=2, label=f"{s.label} (L_we {length / MM:.3g} mm)")
        grid = _load_grid(s)
        ax.plot(grid / length * MM, model_curve("tripp", s.case, grid) / length * MM, "--", color=color, lw=1,
                label="Tripp (t = 3 mm)" if i == 0 else None)
        ax.plot(grid / length * MM, model_curve("palmgren", s.case, grid) / length * MM, ":", color=color, lw=1.2,
                label="Palmgren" if i == 0 else None)
    p = np.geomspace(min(s.all_loads.min() / s.case.roller.contact_length_m for s in group) * 0.8,
                     max(s.all_loads.max() / s.case.roller.contact_length_m for s in group) * 1.1, CURVE_POINTS)
    p = p[p > coeff.p0_n_per_m * 1.05]
    k_fit = EmpiricalFit(coeff, 1.0).stiffness_n_per_m(p)  # one metre of contact: k/L_we at F/L_we = p
    ax.plot(p * MM, k_fit * MM, "k-", lw=1.5, label=f"{coeff.equation} fit")
    ax.fill_between(p * MM, k_fit * MM * (1 - FIT_BAND), k_fit * MM * (1 + FIT_BAND), color="0.85", zorder=0,
                    label="fit ±10 %")
    _finish(ax, "load per contact length F/L_we [N/mm]", "stiffness per contact length k/L_we [N/m per mm]",
            f"measured vs models, rails Ra {coeff.rail_ra_m * 1e6:.3g} µm", legend_size=7)
    return fig


def hertz_verification(group: list[SeriesData]) -> Figure:
    """The ball verification (§2.6): measured means vs Hertz, ±5 %."""
    fig = Figure(figsize=(6.4, 4.4), layout="constrained")
    ax = fig.subplots()
    for i, s in enumerate(group):
        stats = s.step_stats()
        color = f"C{i % 10}"
        ax.plot([st.load_n for st in stats], [st.stiffness_n_per_m for st in stats], "o", color=color, ms=4,
                label=s.label)
        grid = _load_grid(s)
        k = model_curve("hertz", s.case, grid)
        ax.plot(grid, k, "-", color=color, lw=1)
        ax.fill_between(grid, k * (1 - HERTZ_BAND), k * (1 + HERTZ_BAND), color=color, alpha=0.15)
    _finish(ax, "load per ball F [N]", "stiffness k [N/m]", "ball verification: measured vs Hertz (±5 %)")
    return fig


def frf(step: FrfStep) -> Figure:
    """Fig. 7: one step's FRF magnitudes and coherence, the identified modes marked."""
    fig = Figure(figsize=(7.2, 5.6), layout="constrained")
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=(2.2, 1))
    keep = (step.frequencies_hz > 0) & (step.frequencies_hz <= FRF_MAX_HZ)
    f = step.frequencies_hz[keep]
    for c, name in enumerate(step.channels):
        vertical = name.endswith("Z")
        top.semilogy(f, np.abs(step.h1[c, keep]), lw=1.0 if vertical else 0.5, alpha=1.0 if vertical else 0.45,
                     label=name if vertical else None)
        if vertical:
            bottom.plot(f, step.coherence[c, keep], lw=0.6, alpha=0.8, color=top.lines[-1].get_color())
    for kind, freq in step.modes:
        for ax in (top, bottom):
            ax.axvline(freq, color="k" if kind == "bounce" else "0.4", ls="--", lw=0.8)
        top.annotate(f"{kind} {freq:.1f} Hz", (freq, 1.0), xycoords=("data", "axes fraction"), rotation=90,
                     va="top", ha="right", fontsize=7)
    top.set_ylabel("|H1| [(m/s²)/N]")
    top.set_title(f"series {step.series}, repetition {step.run}, step {step.step}: {step.load_n:.1f} N per roller",
                  fontsize=10)
    top.legend(fontsize=7, ncol=4, title="vertical channels (others thin)", title_fontsize=7)
    bottom.set_ylabel("coherence (vertical)")
    bottom.set_xlabel("frequency [Hz]")
    bottom.set_ylim(0, 1.05)
    for ax in (top, bottom):
        ax.grid(alpha=0.3)
    return fig


def frequency_load(series: SeriesData, data: ReportData) -> Figure:
    """Bounce and tilt frequencies vs load, with the rig model driven by the reference stiffness."""
    fig = Figure(figsize=(6.4, 4.4), layout="constrained")
    ax = fig.subplots()
    for i, r in enumerate(series.runs):
        color = f"C{i % 10}"
        ax.plot(r.load_n, r.bounce_hz, "o", color=color, ms=4, label=f"bounce, repetition {r.run}")
        ax.plot(r.load_n, r.tilt_hz[:, 0], "^", color=color, ms=4, mfc="none",
                label=f"tilt, repetition {r.run}")
        ax.plot(r.load_n, r.tilt_hz[:, 1], "v", color=color, ms=4, mfc="none")
    reference = "hertz" if series.kind == "ball" else fit_for_rail(series.case.rail_ra_m)
    grid = _load_grid(series)
    k = model_curve(reference, series.case, grid)
    ok = np.isfinite(k) & (k > 0)
    modes = [rig_modes(data.rig, kk) for kk in k[ok]]
    name = "Hertz" if reference == "hertz" else FITS[reference].equation
    ax.plot(grid[ok], [m.bounce_hz for m in modes], "k-", lw=1, label=f"rig model, bounce ({name} stiffness)")
    ax.plot(grid[ok], [m.tilt_hz[0] for m in modes], "k--", lw=1, label=f"rig model, tilt ({name} stiffness)")
    _finish(ax, "load per roller F [N]", "frequency [Hz]", f"{series.label}: contact-mode frequencies vs load",
            legend_size=7, sci_y=False)
    return fig


def make_figures(data: ReportData) -> Iterator[Plot]:
    """Every figure the campaign has data for, named for its files."""
    measured = [s for s in data.series if s.runs]
    for s in measured:
        yield Plot(f"fig08_load_stiffness_s{s.index:02d}", f"Load–stiffness, {s.label} (cf. Fig. 8)",
                   load_stiffness(s))
    rollers = [s for s in measured if s.kind != "ball"]
    for fit, fig_no in (("fit-ra0.2", 12), ("fit-ra0.03", 13)):
        group = [s for s in rollers if fit_for_rail(s.case.rail_ra_m) == fit]
        if group:
            coeff = FITS[fit]
            yield Plot(f"fig{fig_no}_models_ra{coeff.rail_ra_m * 1e6:g}",
                       f"Measured vs Tripp, Palmgren and {coeff.equation} (cf. Fig. {fig_no})", models(group, fit))
    balls = [s for s in measured if s.kind == "ball"]
    if balls:
        yield Plot("verification_hertz", "Ball verification vs Hertz (cf. §2.6)", hertz_verification(balls))
    if data.frf is not None:
        st = data.frf
        yield Plot(f"fig07_frf_s{st.series:02d}_r{st.run:02d}_step{st.step:03d}",
                   "FRF and coherence of one step (cf. Fig. 7)", frf(st))
    for s in measured:
        yield Plot(f"frequency_load_s{s.index:02d}", f"Frequency vs load, {s.label}", frequency_load(s, data))


def save(plot: Plot, folder: Path) -> tuple[Path, Path]:
    """Write the figure as PNG and SVG; return both paths."""
    png, svg = folder / f"{plot.name}.png", folder / f"{plot.name}.svg"
    plot.figure.savefig(png, dpi=150)
    plot.figure.savefig(svg)
    return png, svg
