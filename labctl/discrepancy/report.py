"""The workflow's findings for people: a text summary and, in a report folder, plots and the JSON document."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import NullFormatter

from labctl.discrepancy.workflow import DiscrepancyResult
from labctl.errors import InputError
from labctl.physics.law import ContactLaw

CURVE_POINTS = 60


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
    lines = [f"{doc['n_points']} points on {doc['n_cases']} roller cases; baseline {doc['baseline']}"
             + (f" (evaluation depth fitted: {depth * 1e3:.3g} mm)" if depth else "")]
    bands = ", ".join(f"{b['sigma'] * 100:.2g} % at {b['load_per_length_n_per_mm']:.3g} N/mm"
                      for b in doc["noise_by_load"])
    lines.append(f"noise floor {doc['noise_floor'] * 100:.2g} % per point ({doc['noise_method']}"
                 + (f"; {bands}" if bands else "") + f"), seating offset σ {doc['seating_sigma'] * 100:.2g} %")
    checks = doc.get("input_checks", {})
    for key, what in (("duplicates", "duplicated rows dropped"), ("conflicting_rows", "conflicting duplicate rows "
                      "dropped"), ("outliers", "gross outliers set aside")):
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


def _log_load_axis(ax: Any) -> None:
    ax.set_xscale("log")
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel("load per roller [N]")


def _grid(n: int) -> tuple[int, int]:
    cols = min(3, n)
    return math.ceil(n / cols), cols


def _case_panels(result: DiscrepancyResult, path: Path, ylabel: str, height: float,
                 draw: Callable[[Any, int], None], sharey: bool = False) -> None:
    """One panel per roller case (load on a log axis), drawn by ``draw(ax, case index)``."""
    rows, cols = _grid(len(result.data.cases))
    fig = Figure(figsize=(4.2 * cols, height * rows), layout="constrained")
    axes = fig.subplots(rows, cols, squeeze=False, sharey=sharey).ravel()
    for i, ax in enumerate(axes[: len(result.data.cases)]):
        draw(ax, i)
        ax.set_title(result.data.cases[i].label, fontsize=8)
        _log_load_axis(ax)
        ax.set_ylabel(ylabel)
    for ax in axes[len(result.data.cases):]:
        ax.set_visible(False)
    axes[0].legend(fontsize=7)
    fig.savefig(path, dpi=110)


def _plot_stiffness(result: DiscrepancyResult, path: Path) -> None:
    def draw(ax: Any, i: int) -> None:
        c = result.data.cases[i]
        ax.loglog(c.load_n, np.exp(c.ln_stiffness), "k.", ms=4, label="measured")
        ax.loglog(*_curve(result.baseline.law, result, i), "C0--", label=f"{result.baseline.spec.baseline} (fitted)")
        if result.steps:
            ax.loglog(*_curve(result.final.law, result, i), "C3-", label="+ " + ", ".join(s.name for s in result.steps))

    _case_panels(result, path, "stiffness [N/m]", 3.2, draw)


def _plot_residuals(result: DiscrepancyResult, path: Path) -> None:
    """Residual per roller case in units of each point's noise σ (symmetric-log axis: the ±2σ band stays
    visible next to residuals of many σ)."""
    slices = result.data.case_slices()

    def draw(ax: Any, i: int) -> None:
        c, sl = result.data.cases[i], slices[i]
        order = np.argsort(c.load_n)
        ax.fill_between(c.load_n[order], -2.0, 2.0, color="0.85", label="±2σ point noise")
        seat = 2.0 * result.noise.seating_sigma / result.baseline.sigma[sl][order]
        if result.noise.seating_sigma > 0:
            ax.plot(c.load_n[order], seat, color="0.5", lw=0.8, ls=":", label="±2σ seating offset")
            ax.plot(c.load_n[order], -seat, color="0.5", lw=0.8, ls=":")
        ax.plot(c.load_n, result.baseline.residuals[sl] / result.baseline.sigma[sl], "C0o", ms=3, label="baseline")
        if result.steps:
            ax.plot(c.load_n, result.final.residuals[sl] / result.final.sigma[sl], "C3.", ms=4, label="final model")
        ax.axhline(0.0, color="k", lw=0.6)
        ax.set_yscale("symlog", linthresh=3.0)

    _case_panels(result, path, "ln(k_model/k_measured) / σ", 2.8, draw, sharey=True)


def _plot_steps(result: DiscrepancyResult, path: Path) -> None:
    """One panel per step of the search: the whitened residuals against load per length before and after it."""
    stages = [("baseline", None, result.baseline)] + [(f"+ {s.name}", s.before, s.fit) for s in result.steps]
    fig = Figure(figsize=(4.2 * len(stages), 3.2), layout="constrained")
    axes = fig.subplots(1, len(stages), squeeze=False, sharey=True).ravel()
    x = result.data.load_per_length_n_per_m * 1e-3
    for ax, (label, before, fit) in zip(axes, stages, strict=True):
        ax.axhspan(-2.0, 2.0, color="0.85", label="±2σ")
        if before is not None:
            ax.plot(x, before.z, ".", color="0.6", ms=3, label="before")
        ax.plot(x, fit.z, "C3.", ms=3, label="after")
        ax.set_xscale("log")
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_yscale("symlog", linthresh=3.0)
        ax.set_xlabel("load per length [N/mm]")
        ax.set_title(f"{label}: gap {fit.gap:.4f}, rms z {fit.score:.2f}", fontsize=8)
    axes[0].set_ylabel("whitened residual z")
    axes[0].legend(fontsize=7)
    fig.savefig(path, dpi=110)


def _plot_gap(result: DiscrepancyResult, path: Path) -> None:
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
    fig.savefig(path, dpi=110)


def _json_default(value: Any) -> Any:
    if isinstance(value, tuple | list | np.ndarray):
        return list(value)
    return float(value)


def write_report(result: DiscrepancyResult, folder: str | Path, doc: dict[str, Any] | None = None) -> list[Path]:
    """Write plots (stiffness, residuals per case, gap per step, one panel per search step), the JSON document
    and the summary; return the files."""
    out = Path(folder)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise InputError(f"--report {out}: exists and is not a folder") from None
    doc = doc if doc is not None else result.to_dict()
    files = [out / "stiffness.png", out / "residuals.png", out / "gap.png", out / "discrepancy.json",
             out / "summary.txt", out / "steps.png"]
    _plot_stiffness(result, files[0])
    _plot_residuals(result, files[1])
    _plot_gap(result, files[2])
    files[3].write_text(json.dumps(doc, indent=2, default=_json_default) + "\n", encoding="utf-8")
    files[4].write_text(summary_text(doc) + "\n", encoding="utf-8")
    _plot_steps(result, files[5])
    return files
