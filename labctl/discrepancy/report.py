"""The workflow's findings for people: a text summary and, in a report folder, plots, an HTML page and the JSON
document. Every figure: load per roller in N, stiffness in N/µm (as in the campaign report), log ticks that read;
a twin campaign's data say SIMULATED, a CSV cannot say ("source: CSV"); a point set aside is drawn and listed."""

from __future__ import annotations

import html
import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import FixedLocator, MaxNLocator, NullFormatter, NullLocator

from labctl.discrepancy.workflow import DiscrepancyResult
from labctl.physics.law import ContactLaw
from labctl.storage.outputs import output_folder

CURVE_POINTS = 60
N_PER_UM = 1e-6  # N/m → N/µm
TICK_STEPS = ((1.0, 2.0, 5.0), (1.0, 1.5, 2.0, 3.0, 5.0, 7.0), tuple(float(m) for m in range(1, 10)))
SIM_MARK = "SIMULATED (digital twin)"
SIM_RED = "#b00000"


@dataclass(frozen=True)
class Source:
    """One input file and what it says about its origin (``simulated`` None: it cannot say, a CSV)."""

    path: str
    kind: str  # "campaign" or "CSV"
    simulated: bool | None
    backend: str = ""

    def describe(self) -> str:
        if self.kind == "CSV":
            return f"{self.path}: source: CSV (a stiffness table does not say whether it was measured or simulated)"
        origin = SIM_MARK if self.simulated else f"measured ({self.backend or 'backend not recorded'})"
        return f"{self.path}: campaign file, {origin}"


def sources_of(paths: Sequence[str | Path]) -> list[Source]:
    """Where each input came from: a campaign file's ``backend`` attribute ("sim": the digital twin)."""
    from labctl.discrepancy.data import HDF5_SUFFIXES

    out = []
    for path in paths:
        if Path(path).suffix.lower() not in HDF5_SUFFIXES:
            out.append(Source(str(path), "CSV", None))
            continue
        from labctl.storage import CampaignReader

        with CampaignReader(path) as reader:
            backend = str(reader.attrs.get("backend", ""))
        out.append(Source(str(path), "campaign", backend == "sim", backend))
    return out


def _mark(fig: Figure, simulated: bool, title: str) -> None:
    """The figure's title; data from the twin say so first, in red."""
    if simulated:
        fig.suptitle(f"{SIM_MARK}\n{title}", color=SIM_RED, fontweight="bold", fontsize=10)  # fits one panel
    else:
        fig.suptitle(title, fontsize=10)


def log_ticks(lo: float, hi: float) -> list[float]:
    """Ticks for a log axis spanning ``lo``..``hi`` that read: 1-2-5 per decade, finer steps when the span is
    too short for three of them, evenly spaced round numbers within a decade (never the two decade ticks of a
    narrow range)."""
    if not (lo > 0 and hi > lo):
        return [lo] if lo > 0 else []
    ticks: list[float] = []
    for mantissas in TICK_STEPS:
        ticks = [m * 10.0**e for e in range(math.floor(math.log10(lo)), math.ceil(math.log10(hi)) + 1)
                 for m in mantissas if lo <= m * 10.0**e <= hi]
        if len(ticks) >= 3:
            return ticks
    for bins in range(3, 12):
        ticks = [float(v) for v in MaxNLocator(bins, steps=[1, 2, 5, 10]).tick_values(lo, hi) if lo <= v <= hi]
        if len(ticks) >= 3:
            break
    return ticks


def _readable_log_axis(axis: Any, lo: float, hi: float) -> None:
    """A log axis with :func:`log_ticks` as plain numbers (no minor labels, no 10^n)."""
    ticks = log_ticks(lo, hi)
    axis.set_major_locator(FixedLocator(ticks))
    axis.set_major_formatter(lambda v, _pos: f"{v:g}")
    axis.set_minor_locator(NullLocator())
    axis.set_minor_formatter(NullFormatter())


def _z_axis(ax: Any, top: float) -> None:
    """A symmetric-log axis of residuals in σ (linear within ±3) with plain ticks up to ``top``."""
    ax.set_yscale("symlog", linthresh=3.0)
    ax.yaxis.set_major_locator(FixedLocator([t for t in (-1000, -100, -30, -10, -2, 0, 2, 10, 30, 100, 1000)
                                             if abs(t) <= max(top * 1.2, 3.0)]))
    ax.yaxis.set_major_formatter(lambda v, _pos: f"{v:g}")
    ax.yaxis.set_minor_locator(NullLocator())


def _span(values: np.ndarray, pad: float = 1.08) -> tuple[float, float]:
    return float(np.min(values)) / pad, float(np.max(values)) * pad


def _pct(ln_ratio: float) -> str:
    ratio = math.exp(ln_ratio)
    return f"model stiffer by {(ratio - 1) * 100:.1f} %" if ratio >= 1 else \
        f"model softer by {(1 - ratio) * 100:.1f} %"


def _step_line(i: int, e: dict[str, Any]) -> str:
    params = ", ".join(f"{k}={v:.4g}" for k, v in e["parameters"].items())
    ev = e["evidence"]
    held = ev.get("held_out")
    held_txt = (f"; held-out ({held['by']}{', weak' if held.get('weak') else ''}) gap {held['gap_without']:.3f} -> "
                f"{held['gap_with']:.3f}") if held else ""
    share = ev.get("explained_share")
    share_txt = f"; explains {share * 100:.0f} % of the discrepancy" if share is not None else ""
    prob = ev.get("probability")
    prob_txt = f"; probability {prob:.2f}" if prob is not None else ""
    return (f"step {i}: + {e['name']} ({params}) gap {e['gap_before']:.4f} -> {e['gap_after']:.4f}; "
            f"dBIC {ev['delta_bic']:.0f}{share_txt}{held_txt}{prob_txt}")


def summary_text(doc: dict[str, Any]) -> str:
    """Human-readable summary of the JSON document of :meth:`DiscrepancyResult.to_dict`."""
    depth = doc["baseline_parameters"].get("depth_m")
    lines = [f"source: {d}" for d in doc.get("sources", [])]  # a twin campaign says SIMULATED first
    lines.append(f"{doc['n_points']} points on {doc['n_cases']} roller cases; baseline {doc['baseline']}"
                 + (f" (evaluation depth fitted: {depth * 1e3:.3g} mm)" if depth else ""))
    bands = ", ".join(f"{b['sigma'] * 100:.2g} % at {b['load_per_length_n_per_mm']:.3g} N/mm"
                      for b in doc["noise_by_load"])
    lines.append(f"noise floor {doc['noise_floor'] * 100:.2g} % per point ({doc['noise_method']}"
                 + (f"; {bands}" if bands else "") + f"), seating offset σ {doc['seating_sigma'] * 100:.2g} %")
    checks = doc.get("input_checks", {})
    for key, what in (("duplicates", "duplicated rows dropped"), ("conflicting_rows", "conflicting duplicate rows "
                      "dropped"), ("outliers", "gross outliers set aside"),
                      ("drifted", "points measured while the load drifted set aside"),
                      ("end_steps", "first or last step(s) off in every seating, kept (see the verdict)")):
        if checks.get(key):
            lines.append(f"input: {len(checks[key])} {what}")
    verdict = "consistent with the noise" if doc["consistent_with_noise"] else "NOT consistent with the noise"
    test = doc["consistency_test"]
    p_txt = f", lack-of-fit p = {test['p']:.2g} at level {test['level']:g}" if "p" in test else ""
    lines.append(f"gap {doc['gap_before']:.4f} -> {doc['gap_after']:.4f} ({verdict}{p_txt})")
    steps = sorted(doc["effects"] + doc["measurement_effects"], key=lambda e: -e["gap_before"])
    if not steps:
        lines.append("no missing effect named" + (": the data agree with the baseline within the noise"
                                                  if doc["consistent_with_noise"] else
                                                  ": no explanation reaches probability 0.9"))
    top = doc.get("explanations", [])[:4]
    if top:
        lines.append("explanations (posterior probability): "
                     + ", ".join(f"{x['explanation']} {x['probability']:.2f}" for x in top))
    lines.extend(_step_line(i, e) for i, e in enumerate(steps, 1))
    if doc["measurement_effects"]:
        lines.append("measurement side (not physics): " + ", ".join(e["name"] for e in doc["measurement_effects"]))
    for w in doc.get("nuisance_warnings", []):
        lines.append("warning: " + w["message"])
    lines.append("verdict: " + doc["verdict_text"])
    emp = doc.get("empirical_term")
    if emp:
        held = emp.get("held_out")
        lines.append(f"unnamed empirical term: {emp['formula']} (gap {emp['gap_before']:.4f} -> {emp['gap_after']:.4f}"
                     + (f"; held-out by {held['by']}: {held['gap_without']:.4f} -> {held['gap_with']:.4f}" if held
                        else "") + ")")
    if doc["regions"]:
        lines.append("where the baseline disagrees beyond the noise:")
    for r in doc["regions"]:
        name = f"type {r['roller_type']}" if r["roller_type"] is not None else f"D {r['diameter_mm']:.3g} mm"
        lines.append(f"  {name}, L_we {r['contact_length_mm']:.4g} mm, {r['material']}, Ra {r['rail_ra_um']:.3g} µm, "
                     f"{r['load_n'][0]:.4g}-{r['load_n'][1]:.4g} N: {_pct(r['mean_residual'])}, "
                     f"residual {r['trend']}")
    return "\n".join(lines)


def _curve(law: ContactLaw, result: DiscrepancyResult, i: int) -> tuple[np.ndarray, np.ndarray]:
    c = result.data.cases[i]
    f = np.geomspace(c.load_n.min(), c.load_n.max(), CURVE_POINTS)
    return f, law.stiffness_n_per_m(c.case, f)


def _log_load_axis(ax: Any, loads_n: np.ndarray) -> None:
    lo, hi = _span(loads_n)
    ax.set_xscale("log")
    ax.set_xlim(lo, hi)
    _readable_log_axis(ax.xaxis, lo, hi)
    ax.set_xlabel("load per roller [N]")


def _grid(n: int) -> tuple[int, int]:
    cols = min(3, n)
    return math.ceil(n / cols), cols


def _set_aside(result: DiscrepancyResult, i: int) -> list[dict[str, Any]]:
    """The gross outliers set aside from roller case ``i`` (matched by its label)."""
    label = result.data.cases[i].label
    return [o for o in result.screening.outliers if o.get("case") == label]


def _case_panels(result: DiscrepancyResult, path: Path, ylabel: str, height: float,
                 draw: Callable[[Any, int], None], title: str, simulated: bool, sharey: bool = False) -> Figure:
    """One panel per roller case (load on a log axis), drawn by ``draw(ax, case index)``."""
    rows, cols = _grid(len(result.data.cases))
    fig = Figure(figsize=(4.2 * cols, height * rows + 0.4), layout="constrained")
    axes = fig.subplots(rows, cols, squeeze=False, sharey=sharey).ravel()
    for i, ax in enumerate(axes[: len(result.data.cases)]):
        draw(ax, i)
        ax.set_title(result.data.cases[i].label, fontsize=8)
        aside = np.array([o["load_n"] for o in _set_aside(result, i)])
        _log_load_axis(ax, np.concatenate([result.data.cases[i].load_n, aside]))
        ax.set_ylabel(ylabel)
    for ax in axes[len(result.data.cases):]:
        ax.set_visible(False)
    handles: dict[str, Any] = {}
    for ax in axes[: len(result.data.cases)]:  # one legend with every kind of mark any panel has
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            handles.setdefault(lab, h)
    axes[0].legend(list(handles.values()), list(handles), fontsize=7)
    _mark(fig, simulated, title)
    fig.savefig(path, dpi=110)
    return fig


def _plot_stiffness(result: DiscrepancyResult, path: Path, simulated: bool = False) -> Figure:
    def draw(ax: Any, i: int) -> None:
        c = result.data.cases[i]
        k = np.exp(c.ln_stiffness) * N_PER_UM
        ax.plot(c.load_n, k, "k.", ms=4, label="measured")
        f, base = _curve(result.baseline.law, result, i)
        ax.plot(f, base * N_PER_UM, "C0--", label=f"{result.baseline.spec.baseline} (fitted)")
        if result.steps:
            f, final = _curve(result.final.law, result, i)
            ax.plot(f, final * N_PER_UM, "C3-", label="+ " + ", ".join(s.name for s in result.steps))
        aside = _set_aside(result, i)
        if aside:
            ax.plot([o["load_n"] for o in aside], [o["stiffness_n_per_m"] * N_PER_UM for o in aside], "x",
                    color=SIM_RED, ms=8, mew=1.5, label="set aside (gross outlier)")
        ax.set_yscale("log")
        lo, hi = _span(np.concatenate([k, base * N_PER_UM, [o["stiffness_n_per_m"] * N_PER_UM for o in aside]]))
        ax.set_ylim(lo, hi)
        _readable_log_axis(ax.yaxis, lo, hi)

    return _case_panels(result, path, "roller stiffness k [N/µm]", 3.2, draw, "measured stiffness and the models",
                 simulated)


def _plot_residuals(result: DiscrepancyResult, path: Path, simulated: bool = False) -> Figure:
    """Residual per roller case in units of each point's noise σ (symmetric-log axis: the ±2σ band stays
    visible next to residuals of many σ); a point set aside is drawn at its baseline residual."""
    slices = result.data.case_slices()
    extreme = [3.0]

    def draw(ax: Any, i: int) -> None:
        c, sl = result.data.cases[i], slices[i]
        order = np.argsort(c.load_n)
        ax.fill_between(c.load_n[order], -2.0, 2.0, color="0.85", label="±2σ point noise")
        seat = 2.0 * result.noise.seating_sigma / result.baseline.sigma[sl][order]
        if result.noise.seating_sigma > 0:
            ax.plot(c.load_n[order], seat, color="0.5", lw=0.8, ls=":", label="±2σ seating offset")
            ax.plot(c.load_n[order], -seat, color="0.5", lw=0.8, ls=":")
        z = result.baseline.residuals[sl] / result.baseline.sigma[sl]
        ax.plot(c.load_n, z, "C0o", ms=3, label="baseline")
        extreme.append(float(np.max(np.abs(z))))
        if result.steps:
            zf = result.final.residuals[sl] / result.final.sigma[sl]
            ax.plot(c.load_n, zf, "C3.", ms=4, label="final model")
            extreme.append(float(np.max(np.abs(zf))))
        for o in _set_aside(result, i):
            f = np.array([o["load_n"]])
            model = result.baseline.law.stiffness_n_per_m(c.case, f)[0]
            sigma = result.baseline.sigma[sl][int(np.argmin(np.abs(c.load_n - o["load_n"])))]
            zo = math.log(model / o["stiffness_n_per_m"]) / sigma
            ax.plot(f, [zo], "x", color=SIM_RED, ms=8, mew=1.5, label="set aside (gross outlier)")
            extreme.append(abs(zo))
        ax.axhline(0.0, color="k", lw=0.6)
        _z_axis(ax, max(extreme))

    return _case_panels(result, path, "ln(k_model/k_measured) / σ", 2.8, draw, "baseline residuals in σ", simulated,
                        sharey=True)


def _plot_steps(result: DiscrepancyResult, path: Path, simulated: bool = False) -> Figure:
    """One panel per step of the search: the whitened residuals against load per roller before and after it."""
    stages = [("baseline", None, result.baseline)] + [(f"+ {s.name}", s.before, s.fit) for s in result.steps]
    fig = Figure(figsize=(4.2 * len(stages), 3.6), layout="constrained")
    axes = fig.subplots(1, len(stages), squeeze=False, sharey=True).ravel()
    x = np.concatenate([c.load_n for c in result.data.cases])
    lo, hi = _span(x)
    for ax, (label, before, fit) in zip(axes, stages, strict=True):
        ax.axhspan(-2.0, 2.0, color="0.85", label="±2σ")
        if before is not None:
            ax.plot(x, before.z, ".", color="0.6", ms=3, label="before")
        ax.plot(x, fit.z, "C3.", ms=3, label="after")
        ax.set_xscale("log")
        ax.set_xlim(lo, hi)
        _readable_log_axis(ax.xaxis, lo, hi)
        _z_axis(ax, max(float(np.max(np.abs(f.z))) for _, _, f in stages))
        ax.set_xlabel("load per roller [N]")
        ax.set_title(f"{label}: gap {fit.gap:.4f}, rms z {fit.score:.2f}", fontsize=8)
    axes[0].set_ylabel("whitened residual z")
    axes[0].legend(fontsize=7)
    _mark(fig, simulated, "search steps")
    fig.savefig(path, dpi=110)
    return fig


def _plot_gap(result: DiscrepancyResult, path: Path, simulated: bool = False) -> Figure:
    labels = [result.baseline.spec.baseline] + [f"+ {s.name}" for s in result.steps]
    gaps = [result.baseline.gap] + [s.fit.gap for s in result.steps]
    fig = Figure(figsize=(1.6 + 1.4 * len(labels), 3.2), layout="constrained")
    ax = fig.subplots()
    ax.bar(range(len(gaps)), gaps, color=["C0"] + ["C3"] * len(result.steps))
    ax.axhline(result.noise.sigma, color="k", ls="--", lw=0.8, label="noise floor (point σ)")
    if result.empirical is not None:
        ax.axhline(result.empirical.gap_after, color="C2", ls=":", lw=0.8, label="with the unnamed empirical term")
    ax.set_xticks(range(len(gaps)), labels, rotation=20, ha="right", fontsize=8)
    ax.set_ylabel("gap: rms ln(k_model/k_measured)")
    ax.legend(fontsize=7)
    _mark(fig, simulated, "gap per step")
    fig.savefig(path, dpi=110)
    return fig


def _json_default(value: Any) -> Any:
    if isinstance(value, tuple | list | np.ndarray):
        return list(value)
    return float(value)


FIGURES = (("stiffness.png", "Measured roller stiffness k [N/µm] against the load per roller [N], with the "
             "fitted baseline and the final model, one panel per roller case."),
            ("residuals.png", "Baseline residual ln(k_model/k_measured) in units of each point's noise σ against "
             "the load per roller [N]; the grey band is ±2σ."),
            ("steps.png", "Whitened residuals of every point before and after each step of the search, against the "
             "load per roller [N]."),
            ("gap.png", "The gap (rms ln(k_model/k_measured)) after each step, against the noise floor."))


def report_html(result: DiscrepancyResult, doc: dict[str, Any], sources: Sequence[Source]) -> str:
    """The report page: where the data came from (SIMULATED for the twin), the verdict, the points set aside,
    the figures with what they show (units named), and the summary."""
    sim = any(s.simulated for s in sources)
    esc = html.escape
    mark = (f'<p class=sim>{SIM_MARK}: the data come from the digital twin, not from a rig.</p>' if sim else "")
    src = "".join(f"<li>{esc(s.describe())}</li>" for s in sources) or "<li>source: not given</li>"
    outliers = result.screening.outliers
    aside = (f"<h2>Points set aside</h2><p>{len(outliers)} gross outlier(s) set aside before every fit (a point "
             "far off its load band's repetitions; drawn as a red × in the figures):</p><table><tr><th>roller case"
             "</th><th>repetition</th><th>load per roller [N]</th><th>stiffness [N/µm]</th></tr>"
             + "".join(f"<tr><td>{esc(str(o['case']))}</td><td>{o['repetition']}</td><td>{o['load_n']:.1f}</td>"
                       f"<td>{o['stiffness_n_per_m'] * N_PER_UM:.2f}</td></tr>" for o in outliers)
             + "</table>" if outliers else "<h2>Points set aside</h2><p>none</p>")
    figs = "".join(f'<figure><img src="{name}" alt="{esc(name)}"><figcaption>{esc(caption)}</figcaption></figure>'
                   for name, caption in FIGURES)
    title = "Discrepancy report" + (f" — {SIM_MARK}" if sim else "")
    return ("<!DOCTYPE html>\n<html lang=en><head><meta charset=utf-8>"
            f"<title>{esc(title)}</title><style>body{{font-family:sans-serif;max-width:60em;margin:1em auto}}"
            f".sim{{color:{SIM_RED};font-weight:bold;font-size:1.3em}}img{{max-width:100%}}"
            "table{border-collapse:collapse}td,th{border:1px solid #999;padding:2px 6px}"
            "figure{break-inside:avoid}</style></head><body>"
            f"<h1>{esc(title)}</h1>{mark}<h2>Source</h2><ul>{src}</ul>"
            f"<h2>Verdict</h2><p>{esc(doc['verdict_text'])}</p>{aside}<h2>Figures</h2>{figs}"
            f"<h2>Summary</h2><pre>{esc(summary_text(doc))}</pre></body></html>\n")


def write_report(result: DiscrepancyResult, folder: str | Path, doc: dict[str, Any] | None = None,
                 sources: Sequence[str | Path] = ()) -> list[Path]:
    """Write plots (stiffness, residuals per case, gap per step, one panel per search step), the HTML page,
    the JSON document and the summary; return the files. ``sources`` are the input files (their origin is
    marked: SIMULATED for a twin campaign, "source: CSV" for a table)."""
    out = output_folder("--report", folder)
    doc = doc if doc is not None else result.to_dict()
    origin = sources_of(sources)
    if origin:
        doc.setdefault("sources", [s.describe() for s in origin])
    sim = any(s.simulated for s in origin)
    files = [out / "stiffness.png", out / "residuals.png", out / "gap.png", out / "discrepancy.json",
             out / "summary.txt", out / "steps.png", out / "index.html"]
    _plot_stiffness(result, files[0], sim)
    _plot_residuals(result, files[1], sim)
    _plot_gap(result, files[2], sim)
    files[3].write_text(json.dumps(doc, indent=2, default=_json_default) + "\n", encoding="utf-8")
    files[4].write_text(summary_text(doc) + "\n", encoding="utf-8")
    _plot_steps(result, files[5], sim)
    files[6].write_text(report_html(result, doc, origin), encoding="utf-8")
    return files
