"""The paper's figures from a campaign (matplotlib, no screen): Fig. 8, Figs. 12–13, Fig. 7, frequency vs load.

Stiffness in N/µm (per contact length: N/µm per mm), FRFs in (m/s²)/N; specimens share a grid of panels;
simulated data say "SIMULATED" in every figure's title.

Each function returns a Figure; :func:`make_figures` names them and :func:`save` writes PNG and SVG.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from labctl.physics import FITS, EmpiricalFit, rig_modes
from labctl.physics.materials import BEARING_STEEL
from labctl.physics.references import fit_for_rail, model_curve
from labctl.report.data import FrfStep, ReportData, SeriesData
from labctl.report.verdict import steel_fit_applies

MM = 1e-3
N_PER_UM = 1e-6  # N/m → N/µm
PER_LENGTH = 1e-9  # (N/m)/m → N/µm per mm
MARKERS = "os^vD<>"
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


def _spread_err(stats: list) -> np.ndarray:
    """Error bars from the mean to the repetitions' min and max (2 × n, never negative)."""
    return np.array([[st.stiffness_n_per_m - st.k_min, st.k_max - st.stiffness_n_per_m] for st in stats]).T.clip(min=0)


def _grid(n: int, panel: tuple[float, float] = (4.6, 3.4), most_columns: int = 3) -> tuple[Figure, list[Axes]]:
    """A figure with ``n`` panels in rows of up to ``most_columns`` (unused cells hidden)."""
    cols = min(n, most_columns)
    rows = -(-n // cols)
    fig = Figure(figsize=(panel[0] * cols, panel[1] * rows + 0.4), layout="constrained")
    axes = np.atleast_1d(fig.subplots(rows, cols, squeeze=False)).ravel().tolist()
    for ax in axes[n:]:
        ax.set_visible(False)
    return fig, axes[:n]


def mark_simulated(fig: Figure, simulated: bool, title: str = "") -> None:
    """A figure of simulated data says so in its title, in red."""
    if simulated:
        fig.suptitle("SIMULATED (digital twin)" + (f" — {title}" if title else ""), color="#b00000",
                     fontweight="bold", fontsize=11)
    elif title:
        fig.suptitle(title, fontsize=11)


def _finish(ax: Axes, xlabel: str, ylabel: str, title: str, legend_size: float | None = 7) -> None:
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=9)
    ax.ticklabel_format(axis="both", useOffset=False, style="plain")  # no "1e7" offsets: units carry the scale
    ax.grid(alpha=0.3)
    if legend_size is not None and ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=legend_size)


def _load_stiffness_panel(ax: Axes, series: SeriesData, legend: bool = True) -> None:
    for i, r in enumerate(series.runs):
        ax.plot(r.load_n, r.stiffness_n_per_m * N_PER_UM, ls="none", marker=MARKERS[i % len(MARKERS)], ms=5,
                mfc="none", color=f"C{i % 10}", label=f"repetition {r.run}")
    stats = series.step_stats()
    f = np.array([s.load_n for s in stats])
    k = np.array([s.stiffness_n_per_m for s in stats])
    ax.fill_between(f, np.array([s.k_min for s in stats]) * N_PER_UM, np.array([s.k_max for s in stats]) * N_PER_UM,
                    color="0.85", label="spread (min–max)")
    ax.plot(f, k * N_PER_UM, "k-", lw=1.2, label="mean")
    _finish(ax, "load per roller F [N]", "roller stiffness k [N/µm]",
            f"{series.label}, rail Ra {series.case.rail_ra_m * 1e6:.3g} µm", legend_size=7 if legend else None)


def load_stiffness(series: SeriesData | list[SeriesData], simulated: bool = False) -> Figure:
    """Fig. 8: stiffness vs load per repetition, with the mean and the spread; one panel per series."""
    group = series if isinstance(series, list) else [series]
    fig, axes = _grid(len(group))
    for i, (ax, s) in enumerate(zip(axes, group, strict=True)):
        _load_stiffness_panel(ax, s, legend=i == 0)
    share_limits(axes[:len(group)])
    mark_simulated(fig, simulated, "load–stiffness per repetition" if len(group) > 1 else "")
    return fig


def share_limits(axes: list[Axes]) -> None:
    """One x and one y range for panels the reader compares side by side (Fig. 8's series)."""
    if len(axes) < 2:
        return
    xs = [ax.get_xlim() for ax in axes]
    ys = [ax.get_ylim() for ax in axes]
    for ax in axes:
        ax.set_xlim(min(x[0] for x in xs), max(x[1] for x in xs))
        ax.set_ylim(min(y[0] for y in ys), max(y[1] for y in ys))


def _material_groups(group: list[SeriesData]) -> list[tuple[str, list[SeriesData]]]:
    by: dict[str, list[SeriesData]] = {}
    for s in group:
        by.setdefault(s.case.roller.material.name, []).append(s)
    return sorted(by.items(), key=lambda kv: (kv[0] != BEARING_STEEL, kv[0]))


def models(group: list[SeriesData], fit: str, simulated: bool = False) -> Figure:
    """Figs. 12/13: measured means per contact length vs Tripp, Palmgren and the fit (Eq. 5 or 6) ±10 %.

    One colour per roller type, its Tripp (dashed) and Palmgren (dotted) curves in the same colour; one panel
    per roller material; the fit (made for steel rollers) only where it applies."""
    coeff = FITS[fit]
    materials = _material_groups(group)
    fig, axes = _grid(len(materials), panel=(6.0, 4.6), most_columns=2)
    colours = {s.index: f"C{i % 10}" for i, s in enumerate(group)}
    for ax, (name, members) in zip(axes, materials, strict=True):
        for s in members:
            length = s.case.roller.contact_length_m
            stats = s.step_stats()
            f = np.array([st.load_n for st in stats])
            k = np.array([st.stiffness_n_per_m for st in stats])
            err = _spread_err(stats)
            colour = colours[s.index]
            ax.errorbar(f / length * MM, k / length * PER_LENGTH, yerr=err / length * PER_LENGTH, fmt="o", ms=4,
                        color=colour, capsize=2, label=f"{s.label} (L_we {length / MM:.3g} mm)")
            grid = _load_grid(s)
            ax.plot(grid / length * MM, model_curve("tripp", s.case, grid) / length * PER_LENGTH, "--",
                    color=colour, lw=1)
            ax.plot(grid / length * MM, model_curve("palmgren", s.case, grid) / length * PER_LENGTH, ":",
                    color=colour, lw=1.2)
        key = [Line2D([], [], color="k", ls="--", lw=1, label="Tripp (t = 3 mm), type's colour"),
               Line2D([], [], color="k", ls=":", lw=1.2, label="Palmgren, type's colour")]
        if name == BEARING_STEEL or steel_fit_applies(members[0])[0]:
            p = np.geomspace(min(s.all_loads.min() / s.case.roller.contact_length_m for s in members) * 0.8,
                             max(s.all_loads.max() / s.case.roller.contact_length_m for s in members) * 1.1,
                             CURVE_POINTS)
            p = p[p > coeff.p0_n_per_m * 1.05]
            k_fit = EmpiricalFit(coeff, 1.0).stiffness_n_per_m(p)  # one metre of contact: k/L_we at F/L_we = p
            ax.plot(p * MM, k_fit * PER_LENGTH, "k-", lw=1.5, label=f"{coeff.equation} fit")
            ax.fill_between(p * MM, k_fit * PER_LENGTH * (1 - FIT_BAND), k_fit * PER_LENGTH * (1 + FIT_BAND),
                            color="0.85", zorder=0, label=f"{coeff.equation} ±{FIT_BAND:.0%}")
            title = f"{name} rollers vs {coeff.equation}, rails Ra {coeff.rail_ra_m * 1e6:.3g} µm"
        else:
            title = f"{name} rollers (not steel: no {coeff.equation}), rails Ra {coeff.rail_ra_m * 1e6:.3g} µm"
        handles, _ = ax.get_legend_handles_labels()
        _finish(ax, "load per contact length F/L_we [N/mm]", "k/L_we [N/µm per mm]", title, legend_size=None)
        ax.legend(handles=handles + key, fontsize=6.5, loc="lower right")
    mark_simulated(fig, simulated, "measured vs models" if len(materials) > 1 else "")
    return fig


def hertz_verification(group: list[SeriesData], simulated: bool = False) -> Figure:
    """The ball verification (§2.6): measured means vs Hertz, ±5 %."""
    fig = Figure(figsize=(6.4, 4.6), layout="constrained")
    ax = fig.subplots()
    for i, s in enumerate(group):
        stats = s.step_stats()
        color = f"C{i % 10}"
        k_mean = np.array([st.stiffness_n_per_m for st in stats])
        err = _spread_err(stats)
        ax.errorbar([st.load_n for st in stats], k_mean * N_PER_UM, yerr=err * N_PER_UM, fmt="o", color=color,
                    ms=4, capsize=2, label=s.label)
        grid = _load_grid(s)
        k = model_curve("hertz", s.case, grid)
        ax.plot(grid, k * N_PER_UM, "-", color=color, lw=1, label=f"Hertz, {s.label}")
        ax.fill_between(grid, k * N_PER_UM * (1 - HERTZ_BAND), k * N_PER_UM * (1 + HERTZ_BAND), color=color,
                        alpha=0.15)
    _finish(ax, "load per ball F [N]", "stiffness k [N/µm]", "ball verification: measured vs Hertz (±5 %)")
    mark_simulated(fig, simulated)
    return fig


def channel_label(name: str) -> str:
    """``A1Z`` → ``A1Z (top, roller 1, vertical)``: where the sensor sits and which way it points."""
    place = {"A1": "top, roller 1", "A2": "top, roller 2", "A3": "top, roller 3", "A4": "bottom centre"}
    axis = {"X": "radial", "Y": "tangential", "Z": "vertical"}
    if len(name) == 3 and name[:2] in place and name[2] in axis:
        return f"{name} ({place[name[:2]]}, {axis[name[2]]})"
    return name


def frf(step: FrfStep, simulated: bool = False) -> Figure:
    """Fig. 7: one step's FRF magnitudes (vertical and horizontal channels apart) and coherence, modes marked."""
    fig = Figure(figsize=(9.6, 7.4), layout="constrained")
    vert, horiz, coh = fig.subplots(3, 1, sharex=True, height_ratios=(2, 2, 1.1))
    keep = (step.frequencies_hz > 0) & (step.frequencies_hz <= FRF_MAX_HZ)
    f = step.frequencies_hz[keep]
    n_h = 0
    for c, name in enumerate(step.channels):
        vertical = name.endswith("Z")
        ax = vert if vertical else horiz
        colour = f"C{(len(vert.lines) if vertical else n_h) % 10}"
        ax.semilogy(f, np.abs(step.h1[c, keep]), lw=0.9, color=colour, label=channel_label(name))
        if vertical:
            coh.plot(f, step.coherence[c, keep], lw=0.8, color=colour, label=name)
        else:
            n_h += 1
    for kind, freq in step.modes:
        for ax in (vert, horiz, coh):
            ax.axvline(freq, color="k" if kind == "bounce" else "0.45", ls="--", lw=0.8)
        vert.annotate(f"{kind} {freq:.1f} Hz", (freq, 1.0), xycoords=("data", "axes fraction"), rotation=90,
                      va="top", ha="right", fontsize=7)
    vert.set_title(f"series {step.series}, repetition {step.run}, step {step.step}: {step.load_n:.1f} N per roller",
                   fontsize=9)
    vert.set_ylabel("|H1| vertical [(m/s²)/N]")
    horiz.set_ylabel("|H1| horizontal [(m/s²)/N]")
    coh.set_ylabel("coherence (vertical)")
    coh.set_xlabel("frequency [Hz]")
    coh.set_ylim(0, 1.02)
    coh.set_xlim(0, FRF_MAX_HZ)
    for ax in (vert, horiz, coh):
        ax.legend(fontsize=10, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0)
    for ax in (vert, horiz, coh):
        ax.grid(alpha=0.3)
    mark_simulated(fig, simulated)
    return fig


def _frequency_panel(ax: Axes, series: SeriesData, data: ReportData, legend: bool = True) -> None:
    for i, r in enumerate(series.runs):
        color = f"C{i % 10}"
        ax.plot(r.load_n, r.bounce_hz, "o", color=color, ms=4, label=f"bounce, repetition {r.run}")
        ax.plot(r.load_n, r.tilt_hz[:, 0], "^", color=color, ms=4, mfc="none", label=f"tilt, repetition {r.run}")
        ax.plot(r.load_n, r.tilt_hz[:, 1], "v", color=color, ms=4, mfc="none")
    reference = "hertz" if series.kind == "ball" else fit_for_rail(series.case.rail_ra_m)
    grid = _load_grid(series)
    k = model_curve(reference, series.case, grid)
    ok = np.isfinite(k) & (k > 0)
    name = "Hertz" if reference == "hertz" else FITS[reference].equation
    if ok.any() and (series.kind == "ball" or steel_fit_applies(series)[0]):
        modes = [rig_modes(data.rig, kk) for kk in k[ok]]
        ax.plot(grid[ok], [m.bounce_hz for m in modes], "k-", lw=1, label=f"rig model, bounce ({name} k)")
        ax.plot(grid[ok], [m.tilt_hz[0] for m in modes], "k--", lw=1, label=f"rig model, tilt ({name} k)")
    _finish(ax, "load per roller F [N]", "frequency [Hz]", f"{series.label}: contact modes vs load",
            legend_size=6 if legend else None)


def frequency_load(series: SeriesData | list[SeriesData], data: ReportData, simulated: bool = False) -> Figure:
    """Bounce and tilt frequencies vs load, with the rig model driven by the reference stiffness; a panel each."""
    group = series if isinstance(series, list) else [series]
    fig, axes = _grid(len(group))
    for i, (ax, s) in enumerate(zip(axes, group, strict=True)):
        _frequency_panel(ax, s, data, legend=i == 0)
    mark_simulated(fig, simulated, "contact-mode frequencies vs load" if len(group) > 1 else "")
    return fig


def is_simulated(data: ReportData) -> bool:
    """Whether the campaign's data come from the digital twin (the file's ``backend`` attribute)."""
    return str(data.attrs.get("backend", "")) == "sim"


def make_figures(data: ReportData) -> Iterator[Plot]:
    """Every figure the campaign has data for, named for its files; series share one grid figure."""
    sim = is_simulated(data)
    measured = [s for s in data.series if s.runs]
    if measured:
        yield Plot("fig08_load_stiffness", "Load–stiffness per specimen (cf. Fig. 8)", load_stiffness(measured, sim))
    rollers = [s for s in measured if s.kind != "ball"]
    for fit, fig_no in (("fit-ra0.2", 12), ("fit-ra0.03", 13)):
        group = [s for s in rollers if fit_for_rail(s.case.rail_ra_m) == fit]
        if group:
            coeff = FITS[fit]
            yield Plot(f"fig{fig_no}_models_ra{coeff.rail_ra_m * 1e6:g}",
                       f"Measured vs Tripp, Palmgren and {coeff.equation} (cf. Fig. {fig_no})",
                       models(group, fit, sim))
    balls = [s for s in measured if s.kind == "ball"]
    if balls:
        yield Plot("verification_hertz", "Ball verification vs Hertz (cf. §2.6)", hertz_verification(balls, sim))
    if data.frf is not None:
        st = data.frf
        yield Plot(f"fig07_frf_s{st.series:02d}_r{st.run:02d}_step{st.step:03d}",
                   "FRF and coherence of one step (cf. Fig. 7)", frf(st, sim))
    if measured:
        yield Plot("frequency_load", "Contact-mode frequencies vs load per specimen",
                   frequency_load(measured, data, sim))


def save(plot: Plot, folder: Path) -> tuple[Path, Path]:
    """Write the figure as PNG and SVG; return both paths. The SVG keeps the layout the PNG's drawing computed (the
    layout is a third of a report's drawing time; the two differ by a fraction of a point)."""
    png, svg = folder / f"{plot.name}.png", folder / f"{plot.name}.svg"
    plot.figure.savefig(png, dpi=150)
    plot.figure.set_layout_engine("none")
    plot.figure.savefig(svg)
    return png, svg
