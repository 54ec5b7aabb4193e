"""The discrepancy workflow: fit the baseline, measure the noise, locate the gap, add effects until it closes.

Steps (issue 7): (1) the baseline for every point with its nuisance parameters fitted (Tripp's depth);
(2) the noise floor from the repetitions; (3) regions where residuals exceed the noise; (4) candidate effects
ranked by BIC with a held-out check; (5) add the named effect and refit; (6) repeat until the residuals are
consistent with the noise; (7) the gap before and after each step.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from labctl.discrepancy.data import Dataset, build_dataset, load_points
from labctl.discrepancy.locate import locate, trends
from labctl.discrepancy.model import Fit, ModelSpec, fit_model
from labctl.discrepancy.noise import NoiseFloor, estimate_noise
from labctl.discrepancy.search import Step, select_step
from labctl.errors import InputError
from labctl.physics.effects import EFFECTS
from labctl.physics.law import BASELINES
from labctl.physics.rig_config import load_rig
from labctl.stiffness_table import StiffnessPoint


@dataclass(frozen=True)
class DiscrepancyResult:
    """Everything the workflow found: the fits before and after, the steps, the noise and the regions."""

    data: Dataset
    baseline: Fit
    final: Fit
    noise: NoiseFloor
    steps: tuple[Step, ...]
    regions: list[dict[str, Any]]
    """Where the fitted baseline disagrees with the data beyond the noise."""
    regions_after: list[dict[str, Any]]
    """Where the final model still does."""
    trends: list[dict[str, Any]]

    @property
    def consistent(self) -> bool:
        return consistent_with_noise(self.final, self.noise)

    def to_dict(self) -> dict[str, Any]:
        """The JSON document of ``labctl discrepancy --json``."""
        params = self.final.effect_parameters()
        return {
            "baseline": self.baseline.spec.baseline,
            "baseline_parameters": self.baseline.baseline_parameters(),
            "final_baseline_parameters": self.final.baseline_parameters(),
            "n_points": self.data.n_points,
            "n_cases": len(self.data.cases),
            "gap_before": self.baseline.gap,
            "gap_after": self.final.gap,
            "noise_floor": self.noise.sigma,
            "noise_method": self.noise.method,
            "consistent_with_noise": self.consistent,
            "noise_by_load": self.noise.bands(),
            "lack_of_fit_p": self.noise.lack_of_fit_p(self.final.z, self.final.spec.n_params()),
            "effects": [
                {"name": s.name, "parameters": params[s.name], "evidence": s.evidence,
                 "gap_before": s.before.gap, "gap_after": s.fit.gap}
                for s in self.steps
            ],
            "regions": self.regions,
            "regions_after": self.regions_after,
            "trends": self.trends,
        }


def consistent_with_noise(fit: Fit, noise: NoiseFloor) -> bool:
    """No lack of fit beyond the pure error, or a systematic misfit no larger than the noise itself."""
    return noise.consistent(fit.z, fit.spec.n_params())


def run_discrepancy(points: Sequence[StiffnessPoint], baseline: str = "tripp", *,
                    setup_stiffness_n_per_m: float | None = None, max_effects: int = len(EFFECTS)
                    ) -> DiscrepancyResult:
    """Run the whole workflow on measured points; K_setup defaults to the shipped rig file's nominal value."""
    if baseline not in BASELINES:
        raise InputError(f"unknown baseline {baseline!r}; expected one of {', '.join(BASELINES)}")
    data = build_dataset(points)
    k_setup = setup_stiffness_n_per_m or load_rig().setup_stiffness_n_per_m
    spec = ModelSpec(baseline, (), {"setup_compliance": {"nominal_setup_n_per_m": k_setup}})
    noise = estimate_noise(data)
    base = fit_model(data, spec, sigma=noise.sigma_at(data))
    current, steps = base, []
    while len(steps) < max_effects and not consistent_with_noise(current, noise):
        new = select_step(data, current, noise)
        if not new:
            break
        steps.extend(new[: max_effects - len(steps)])
        current = steps[-1].fit
    return DiscrepancyResult(
        data=data, baseline=base, final=current, noise=noise, steps=tuple(steps),
        regions=locate(data, base.residuals, base.sigma), regions_after=locate(data, current.residuals, current.sigma),
        trends=trends(data, base.residuals, noise.sigma),
    )


def run_files(paths: Sequence[str | Path], baseline: str = "tripp") -> DiscrepancyResult:
    """The workflow on stiffness tables and campaign files: the entry point of ``labctl discrepancy``."""
    return run_discrepancy(load_points(paths), baseline)
