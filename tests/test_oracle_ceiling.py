"""The oracle ceiling of the blind worlds (bench/oracle_ceiling.py): its likelihood is the generator's noise model,
and on a nearly noise-free world of one effect it names the truth first."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import multivariate_normal

_PATH = Path(__file__).resolve().parents[1] / "bench" / "oracle_ceiling.py"
_spec = importlib.util.spec_from_file_location("oracle_ceiling", _PATH)
oc = importlib.util.module_from_spec(_spec)
sys.modules["oracle_ceiling"] = oc
_spec.loader.exec_module(oc)


def test_labels_follow_the_bench() -> None:
    """Classes as the bench names truths: library effects in the workflow's order, then the calibration."""
    assert oc.label(["end_effects", "surface_roughness"], []) == "surface_roughness + end_effects"
    assert oc.label(["misalignment"], ["load_gain"]) == "misalignment + load_gain"
    assert oc.label([], []) == "none"


def test_likelihood_is_the_seating_gaussian_without_faults(monkeypatch: pytest.MonkeyPatch) -> None:
    """With the outlier fault switched off, ln L is the multivariate normal of each repetition (point σ and one
    shared seating offset), summed."""
    ds = oc.W.generate("setup_compliance", 1, 1.0)
    world = oc.World(ds.rows, ds.truth["noise"])
    lnk = world.base.ln_tripp + 0.003
    monkeypatch.setattr(oc, "P_OUTLIERS", 1e-300)
    r = world.y - lnk.reshape(world.shape)
    want = sum(multivariate_normal(np.zeros(11), np.diag(world.base.var[i, j]) + world.tau2).logpdf(r[i, j])
               for i in range(r.shape[0]) for j in range(r.shape[1]))
    assert world.lnlike(lnk, world.base) == pytest.approx(want, abs=1e-6)


def test_a_nearly_noise_free_single_effect_is_named_first() -> None:
    """End effects at noise scale 0.05: the oracle's first class is the truth, by a wide margin."""
    ds = oc.W.generate("end_effects", 0, 0.05)
    post = oc.classify(ds.rows, ds.truth["noise"])
    first, second = list(post.items())[:2]
    assert first[0] == "end_effects"
    assert first[1] - second[1] > 5.0


def test_free_depth_moves_tripp_as_the_contact_model_does(monkeypatch: pytest.MonkeyPatch) -> None:
    """Tripp's stiffness at depth 3 mm·e^δ is k_tripp/(1 + β·δ), exactly: what ``--free-depth`` integrates over."""
    import blind_contact  # on the path once the oracle is loaded (it puts bench/blind there)

    ds = oc.W.generate("none", 0, 1.0)
    world = oc.World(ds.rows, ds.truth["noise"], True)
    st, delta = world.base, 0.8
    monkeypatch.setattr(blind_contact, "DEPTH_M", blind_contact.DEPTH_M * np.exp(delta))
    moved = np.log(st.stack.tripp()).reshape(world.shape)
    assert moved == pytest.approx(st.ln_tripp.reshape(world.shape) - np.log1p(st.beta * delta), abs=1e-12)


def test_free_depth_takes_up_a_depth_change_a_fixed_depth_cannot() -> None:
    """Null data at a shallower depth (δ = −0.5): with the depth free their likelihood under Tripp at 3 mm is far
    above the one with the depth fixed, and a little below the one at the true depth (the integral over a flat prior
    on ln t: the peak times its width over the prior's)."""
    ds = oc.W.generate("none", 0, 1.0)
    fixed, free = oc.World(ds.rows, ds.truth["noise"]), oc.World(ds.rows, ds.truth["noise"], True)
    st, delta = free.base, -0.5
    at_true_depth = fixed.lnlike(st.ln_tripp, st)
    fixed.y = free.y = fixed.y - np.log1p(st.beta * delta)
    assert fixed.lnlike(st.ln_tripp, st) < at_true_depth - 100.0
    assert at_true_depth - 15.0 < free.lnlike(st.ln_tripp, st) < at_true_depth
