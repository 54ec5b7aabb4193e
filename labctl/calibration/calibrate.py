"""From campaign files to a calibration: read the ball steps, fit the rig, say what is and is not determined."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from labctl import __version__
from labctl.calibration.data import BallStep, read_ball_steps
from labctl.calibration.fit import DETERMINED_REL, PARAMETERS, FitResult, fit_rig, rig_values
from labctl.calibration.rigfile import calibrated_rig_text
from labctl.errors import InputError
from labctl.physics.rig_config import RigConfig, load_rig, rig_from_text

ALWAYS_INSEPARABLE = (
    "upper vs lower disc mass: bounce and tilt depend on the two discs only through their reduced mass, so "
    "mass_kg is the mass of each disc taken equal (as in Eq. 4)",
    "upper vs lower disc inertia: likewise only their reduced inertia enters the tilt modes",
    "the balls' Hertz stiffness scale: mass_kg is in proportion to E*^(2/3) of the ball material assumed "
    "(1 % in E* is 0.67 % in mass), so the calibration is as good as the balls' elastic constants",
)
UNITS = {"mass_kg": "kg", "setup_stiffness_n_per_m": "N/m", "inertia_kg_m2": "kg·m²",
         "support_stiffness_n_per_m": "N/m"}
# Ground balls reseat far more repeatably than this (the paper: ball stiffness std below 3 %); more scatter
# than this means the contacts are not Hertz (dirt, damage, wrong material) or the campaigns are not of one rig.
PLAUSIBLE_SEATING_SCATTER = 0.03
STD_KEYS = {"mass_kg": "mass_std_kg", "setup_stiffness_n_per_m": "setup_stiffness_std_n_per_m",
            "inertia_kg_m2": "inertia_std_kg_m2", "support_stiffness_n_per_m": "support_stiffness_std_n_per_m"}


@dataclass
class Calibration:
    """The fit of one or more ball campaigns against a nominal rig, and where that rig came from."""

    fit: FitResult
    nominal: RigConfig
    nominal_text: str
    campaigns: list[str]
    steps: list[BallStep]
    skipped: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """The ``labctl calibrate --json`` object (null where the data do not determine a parameter)."""
        f = self.fit
        out: dict[str, Any] = {}
        for p in PARAMETERS:
            out[p] = f.values[p] if p in f.free else None
            out[STD_KEYS[p]] = f.std[p]
        both = "mass_kg" in f.free and "setup_stiffness_n_per_m" in f.free
        out["mass_setup_correlation"] = f.correlation["mass_kg"]["setup_stiffness_n_per_m"] if both else None
        out["correlation"] = {p: {q: c for q, c in row.items() if q in f.free}
                              for p, row in f.correlation.items() if p in f.free}
        out["nominal"] = rig_values(self.nominal)
        out["not_determined"] = [
            {"parameter": p, "held_at": f.values[p], "why": why,
             "fit_not_used": None if p not in f.unseparated_fit else
             {"value": f.unseparated_fit[p][0], "std": f.unseparated_fit[p][1]}}
            for p, why in f.held.items()]
        out["cannot_separate"] = [f"{p}: {why}" for p, why in f.held.items()] + list(ALWAYS_INSEPARABLE)
        resid = np.array([r["whitened"] for r in f.residuals])
        out["fit"] = {
            "chi2": f.chi2, "dof": f.dof, "chi2_per_dof": f.chi2 / f.dof if f.dof else None,
            "seating_scatter_rel": f.seating_scatter_rel, "frequency_scatter_rel": f.frequency_scatter_rel,
            "error_scale": f.error_scale, "coverage_factors": f.coverage_factors, "load_noise_n": f.load_noise_n,
            "max_abs_whitened_residual": float(np.max(np.abs(resid))) if resid.size else None,
            "rms_residual_rel": {mode: _rms_rel(f.residuals, mode) for mode in ("bounce", "tilt")},
            "determined_below_rel": DETERMINED_REL,
        }
        out["warnings"] = self.warnings()
        out["ball_sizes_mm"] = f.ball_sizes_mm
        out["steps"] = len(self.steps)
        out["campaigns"] = self.campaigns
        out["nominal_rig"] = self.nominal.source
        out["skipped"] = self.skipped
        out["residuals"] = f.residuals
        return out

    def warnings(self) -> list[str]:
        """Reasons not to trust the fit although it converged."""
        out = []
        s = self.fit.seating_scatter_rel
        if s > PLAUSIBLE_SEATING_SCATTER:
            out.append(f"the ball stiffness scatters by {100 * s:.3g} % per seating to explain the data, more than "
                       f"the {100 * PLAUSIBLE_SEATING_SCATTER:g} % Hertz contacts of ground balls allow: the balls "
                       "are not Hertz contacts (dirt, damage, another material) or the campaigns are not of one "
                       "rig; do not use this calibration")
        seatings: dict[float, set[str]] = {}
        for step in self.steps:
            seatings.setdefault(round(step.ball_diameter_m * 1e3, 6), set()).add(step.run_key)
        once = sorted(d for d, runs in seatings.items() if len(runs) < 2)
        if once:
            out.append(f"ball size(s) {', '.join(f'{d:g} mm' for d in once)} seated only once: the seating "
                       "scatter, which limits the mass, cannot be told from the rig parameters, so the "
                       "uncertainties leave it out; repeat with at least two repetitions per ball size")
        return out

    def rig_text(self) -> str:
        """The calibrated rig file (the nominal file with the determined values, uncertainty and provenance)."""
        f = self.fit
        provenance: dict[str, Any] = {
            "method": "labctl calibrate: rig modes fitted to ball runs with Hertz contacts",
            "created_utc": datetime.now(UTC).isoformat(timespec="seconds"),
            "software_version": __version__,
            "nominal_rig": self.nominal.source,
            "campaigns": self.campaigns,
            "ball_sizes_mm": f.ball_sizes_mm,
            "steps": len(self.steps),
            "determined": list(f.free),
            "not_determined": [f"{p}: {why}" for p, why in f.held.items()],
            "chi2": f.chi2,
            "dof": f.dof,
            "seating_scatter_rel": f.seating_scatter_rel,
            "model_rel": self.nominal.uncertainty.model_rel,
        }
        return calibrated_rig_text(self.nominal_text, self.nominal.source, f, provenance)


def _rms_rel(residuals: list[dict], mode: str) -> float | None:
    d = [(r["measured_hz"] - r["model_hz"]) / r["model_hz"] for r in residuals if r["mode"] == mode]
    return math.sqrt(float(np.mean(np.square(d)))) if d else None


def _refuse_duplicates(paths: Sequence[str | Path]) -> None:
    """The same campaign given twice (the same file, a link to it, or a copy: same creation time, protocol and
    seed) would count its steps twice and shrink every σ as if twice the data were there: refused."""
    from labctl.storage import CampaignReader
    from labctl.storage.outputs import same_file

    seen: list[tuple[str | Path, tuple[object, ...]]] = []
    for p in paths:
        with CampaignReader(p) as reader:
            a = reader.attrs
        identity = (a.get("created_utc"), a.get("protocol_name"), a.get("seed"), a.get("backend"))
        for q, other in seen:
            if same_file(p, q):
                raise InputError(f"{p}: given twice (also as {q}); give each campaign once")
            if identity == other and identity[0]:
                raise InputError(f"{p}: the same campaign as {q} (created {identity[0]}, same protocol and seed): "
                                 "a copy would count its steps twice; give each campaign once")
        seen.append((p, identity))


def calibrate(paths: Sequence[str | Path], rig: str | Path | None = None, *, use_tilt: bool = True) -> Calibration:
    """Fit the rig to the ball steps of the campaign files, against ``rig`` (default: the campaigns' stored rig)."""
    if not paths:
        raise InputError("no campaign files given")
    _refuse_duplicates(paths)
    campaigns = [read_ball_steps(p) for p in paths]
    if rig is not None:
        load_rig(rig)  # names the file and the field of any error
        text, source = Path(rig).read_text(encoding="utf-8"), str(rig)
    else:
        stored = [(c.path, c.rig_text) for c in campaigns]
        text, source = stored[0][1], f"{stored[0][0]}:/config/rig.toml"
        if text is None:
            raise InputError(f"{stored[0][0]}: no rig description stored; give the nominal rig with --rig")
        for path, other in stored[1:]:
            if other != text:
                raise InputError(f"{path}: stored a different rig description than {stored[0][0]}; "
                                 "give the nominal rig with --rig")
    nominal = rig_from_text(text, source) if rig is None else load_rig(rig)
    steps = [s for c in campaigns for s in c.steps]
    skipped = [m for c in campaigns for m in c.skipped]
    if not steps:
        raise InputError(f"{', '.join(map(str, paths))}: no identified ball steps (a ball-verification or "
                         "calibration protocol's campaign is needed)")
    return Calibration(fit_rig(nominal, steps, use_tilt=use_tilt), nominal, text, [str(p) for p in paths], steps,
                       skipped)
