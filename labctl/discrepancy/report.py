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


def summary_text(doc: dict[str, Any]) -> str:
    """Human-readable summary of the JSON document of :meth:`DiscrepancyResult.to_dict`."""
    depth = doc["baseline_parameters"].get("depth_m")
    lines = [f"{doc['n_points']} points on {doc['n_cases']} roller cases; baseline {doc['baseline']}"
             + (f" (evaluation depth fitted: {depth * 1e3:.3g} mm)" if depth else "")]
    bands = ", ".join(f"{b['sigma'] * 100:.2g} % at {b['load_per_length_n_per_mm']:.3g} N/mm"
                      for b in doc["noise_by_load"])
    lines.append(f"noise floor {doc['noise_floor'] * 100:.2g} % ({doc['noise_method']}" + (f"; {bands})" if bands
                                                                                           else ")"))
    verdict = "consistent with the noise" if doc["consistent_with_noise"] else "NOT consistent with the noise"
    lines.append(f"gap {doc['gap_before']:.4f} -> {doc['gap_after']:.4f} ({verdict})")
    if not doc["effects"]:
        lines.append("no missing effect named" + (": the data agree with the baseline within the noise"
                                                  if doc["consistent_with_noise"] else
                                                  ": no candidate's evidence was decisive"))
    for i, e in enumerate(doc["effects"], 1):
        params = ", ".join(f"{k}={v:.4g}" for k, v in e["parameters"].items())
        ev = e["evidence"]
        held = ev.get("held_out")
        held_txt = f"; held-out gap {held['gap_without']:.3f} -> {held['gap_with']:.3f}" if held else ""
        lines.append(f"step {i}: + {e['name']} ({params}) gap {e['gap_before']:.4f} -> {e['gap_after']:.4f}; "
                     f"dBIC {ev['delta_bic']:.0f}{held_txt}")
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
    slices = result.data.case_slices()

    def draw(ax: Any, i: int) -> None:
        c, sl = result.data.cases[i], slices[i]
        order = np.argsort(c.load_n)
        band = 2 * result.baseline.sigma[sl][order]
        ax.fill_between(c.load_n[order], -band, band, color="0.85", label="±2σ noise")
        ax.plot(c.load_n, result.baseline.residuals[sl], "C0o", ms=3, label="baseline")
        if result.steps:
            ax.plot(c.load_n, result.final.residuals[sl], "C3.", ms=4, label="final model")
        ax.axhline(0.0, color="k", lw=0.6)

    _case_panels(result, path, "ln(k_model / k_measured)", 2.8, draw, sharey=True)


def _plot_gap(result: DiscrepancyResult, path: Path) -> None:
    labels = [result.baseline.spec.baseline] + [f"+ {s.name}" for s in result.steps]
    gaps = [result.baseline.gap] + [s.fit.gap for s in result.steps]
    fig = Figure(figsize=(1.6 + 1.4 * len(labels), 3.2), layout="constrained")
    ax = fig.subplots()
    ax.bar(range(len(gaps)), gaps, color=["C0"] + ["C3"] * len(result.steps))
    ax.axhline(result.noise.sigma, color="k", ls="--", lw=0.8, label="noise floor")
    ax.set_xticks(range(len(gaps)), labels, rotation=20, ha="right", fontsize=8)
    ax.set_ylabel("gap: rms ln(k_model/k_measured)")
    ax.legend(fontsize=7)
    fig.savefig(path, dpi=110)


def write_report(result: DiscrepancyResult, folder: str | Path, doc: dict[str, Any] | None = None) -> list[Path]:
    """Write plots (stiffness, residuals, gap per step), the JSON document and the summary; return the files."""
    out = Path(folder)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise InputError(f"--report {out}: exists and is not a folder") from None
    doc = doc if doc is not None else result.to_dict()
    files = [out / "stiffness.png", out / "residuals.png", out / "gap.png", out / "discrepancy.json",
             out / "summary.txt"]
    _plot_stiffness(result, files[0])
    _plot_residuals(result, files[1])
    _plot_gap(result, files[2])
    files[3].write_text(json.dumps(doc, indent=2, default=float) + "\n", encoding="utf-8")
    files[4].write_text(summary_text(doc) + "\n", encoding="utf-8")
    return files
