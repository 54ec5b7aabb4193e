"""The step result is built from the processing's Identification field by named field (``result_of``): every
value lands in the field of its name, and a missing or renamed attribute fails loudly instead of leaving a
default (the former copy by matching names skipped a misspelt field silently)."""

from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace

import numpy as np
import pytest

from labctl.processing import Identification, ImpactCheck, Mode
from labctl.recording import result_of
from labctl.storage.records import STRUCTURED_FIELDS, StepResult


def _identification() -> Identification:
    """An identification whose every field holds a value of its own (so a crossed wire shows)."""
    modes = [Mode("bounce", 700.5, 0.5, 0.011, 0.001, {"A1Z": 1.0}, 0.97, 0.02, 0.995),
             Mode("tilt", 900.25, 0.75, 0.012, 0.002, {"A1X": 1.0}, 0.1, 0.9, 0.98)]
    checks = [ImpactCheck(0, True, (), 800.0, 3e-4), ImpactCheck(1, False, ("double_hit",), 700.0, 3.2e-4)]
    f = np.linspace(0.0, 100.0, 3)
    return Identification(
        bounce_hz=np.float64(700.5), bounce_hz_std=0.5, bounce_damping_ratio=0.011, bounce_damping_ratio_std=0.001,
        tilt_hz=(900.25, 910.5), tilt_hz_std=(0.75, 0.8), tilt_pair_resolved=np.bool_(True),
        roller_stiffness_n_per_m=3.1e7, roller_stiffness_std_n_per_m=2.2e5, coherence_at_bounce=0.995,
        impacts=checks, frequencies_hz=f, h1=np.ones((2, 3), complex), h2=np.ones((2, 3), complex),
        coherence=np.full((2, 3), 0.9), channels=("A1X", "A1Z"), modes=modes, fs_hz=20480.0,
        window_decay_rate_per_s=12.5, fit_band_hz=np.array([600.0, 1100.0]), dead_channels=("A4Z",),
        dropped_channels=("A3Y",), classified_by_shape=False, roller_only_stiffness_n_per_m=3.3e7,
        roller_only_stiffness_std_n_per_m=2.4e5, warnings=["rollers differ"],
        roller_stiffnesses_n_per_m=np.array([3.0e7, 3.1e7, 3.2e7]), roller_stiffnesses_std_n_per_m=(1e5, 2e5, 3e5),
        roller_stiffnesses_fit_std_n_per_m=(1.0, 2.0, 3.0), roller_stiffnesses_resolved=True,
        roller_stiffness_condition=4.5, rollers_differing=(3,), roller_stiffness_budget_n_per_m={"modal fit": 1e5},
        linearity={"slope": 0.1}, small_blow={"shift_hz": 0.2})


def test_every_result_field_carries_the_identification_value_of_its_name():
    ident = _identification()
    result = result_of(ident, [4, 7])
    for f in dataclasses.fields(StepResult):
        if f.name in STRUCTURED_FIELDS or f.name == "error":
            continue
        mine, theirs = getattr(result, f.name), getattr(ident, f.name)
        if isinstance(theirs, np.ndarray | list | tuple):
            assert isinstance(mine, tuple) and list(mine) == list(np.asarray(theirs).tolist()), f.name
        else:
            assert mine == theirs and not isinstance(mine, np.generic), f.name
    assert result.impacts[1].attempt == 7 and not result.impacts[1].used and result.used_attempts == (4,)
    assert [m.frequency_hz for m in result.modes] == [700.5, 900.25] and result.modes[1].tilt_fraction == 0.9
    assert result.frf is not None and result.frf.h1.shape == (2, 3) and result.identified and not result.error
    assert math.isfinite(result.roller_only_stiffness_n_per_m)


def test_a_missing_or_renamed_identification_attribute_fails_loudly():
    ident = _identification()
    renamed = {k: v for k, v in vars(ident).items() if k != "roller_stiffness_std_n_per_m"}
    renamed["roller_stiffness_sd_n_per_m"] = ident.roller_stiffness_std_n_per_m
    with pytest.raises(AttributeError, match="roller_stiffness_std_n_per_m"):
        result_of(SimpleNamespace(**renamed), [1, 2])  # type: ignore[arg-type]
