"""What is set aside before the decision, each reported in the screening: duplicated and conflicting rows and
unit slips (``labctl.discrepancy.screen``), gross outliers against the local repetition spread
(``labctl.discrepancy.outliers``), and the repetitions of one load step out of line with a model
(``labctl.discrepancy.step_outliers``), taken only when the model then agrees with the rest within the noise.
"""

from __future__ import annotations

from collections.abc import Sequence

from labctl.discrepancy.data import Dataset, build_dataset
from labctl.discrepancy.model import Fit, ModelSpec
from labctl.discrepancy.noise import NoiseFloor, estimate_noise, lack_of_fit_rejects
from labctl.discrepancy.screen import Screening, check_units, screen_points
from labctl.discrepancy.search import Search
from labctl.discrepancy.step_outliers import step_out_of_line, step_too_spread
from labctl.stiffness_table import StiffnessPoint


def consistent_with_noise(fit: Fit, noise: NoiseFloor, data: Dataset) -> bool:
    """The lack-of-fit test at level CONSISTENT_P finds no structure beyond the noise."""
    p = fit.lack_of_fit_p(data, noise)
    return p is not None and not lack_of_fit_rejects(p)


def set_aside_outliers(data: Dataset, screening: Screening) -> tuple[Dataset, NoiseFloor]:
    """Estimate the noise, setting gross outliers aside (reported) until none is left."""
    noise = estimate_noise(data)
    for _ in range(3):
        if not noise.outliers:
            break
        data = screening.set_aside(data, noise.outliers)
        noise = estimate_noise(data)
    return data, noise


def set_aside_step(data: Dataset, noise: NoiseFloor, spec: ModelSpec, screening: Screening,
                   warm: Fit | None = None, against: str = "the baseline") -> tuple[Dataset, NoiseFloor]:
    """The repetitions of one load step out of line with the model ``spec`` set aside (reported): a step whose mean
    is out of line (``step_out_of_line``) when the model then agrees with the rest within the noise; else a step
    whose spread is out of line (``step_too_spread``) unless the model agreed with the data before and not after
    (then the spread decided the verdict, and the noise model cannot tell it from two bad points). Else the data
    as they were. ``warm``: a fit of ``spec`` already at hand, to start from; ``against``: what ``spec`` is, in
    the words of a seating's end step that alone departs from it (noted, not set aside)."""
    fit = Search(data, noise).fit(spec, warm=warm)
    bad, end_step, end = step_out_of_line(data, noise, fit.residuals, fit.sigma, spec.n_params())
    if end_step:
        screening.note_end_step(data, end_step, end, fit.residuals, against)
    spread = [] if bad else step_too_spread(data, noise, fit.residuals, fit.sigma)
    if not bad and not spread:
        return data, noise
    trial = Screening()
    fewer, less = set_aside_outliers(trial.set_aside(data, bad or spread), trial)
    after = consistent_with_noise(Search(fewer, less).fit(spec, warm=fit), less, fewer)
    if not after and (bad or consistent_with_noise(fit, noise, data)):
        return data, noise
    screening.outliers.extend(trial.outliers)
    return fewer, less


def screened(points: Sequence[StiffnessPoint], spec: ModelSpec) -> tuple[Dataset, NoiseFloor, Screening]:
    """Steps 0-1: the rows screened, the noise modelled, gross outliers and a load step out of line with the
    baseline ``spec`` set aside (all reported in the screening)."""
    kept, screening = screen_points(points)
    data = build_dataset(kept)
    check_units(data)
    data, noise = set_aside_outliers(data, screening)
    data, noise = set_aside_step(data, noise, spec, screening)
    return data, noise, screening
