"""The common shape of a contact model: stiffness (and deflection, where defined) vectorised over load."""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from labctl.errors import ModelDomainError

FloatArray = NDArray[np.float64]


@runtime_checkable
class ContactModel(Protocol):
    """A load-stiffness law for one rolling element between two flats (loads in N, result in N/m)."""

    name: str

    def stiffness_n_per_m(self, load_n: ArrayLike) -> FloatArray:
        """Tangent stiffness dF/dδ of the element with both its contacts, at each load."""
        ...

    def deflection_m(self, load_n: ArrayLike) -> FloatArray | None:
        """Total approach δ of the two flats at each load, or None where the model does not define it."""
        ...


def as_load(load_n: ArrayLike, model: str) -> FloatArray:
    """Loads as a float array; zero, negative or non-finite loads are refused with the model's name."""
    f = np.asarray(load_n, dtype=float)
    if (f > 0).all() and np.isfinite(f).all():  # the hot path of every fit: two array methods, no wrapper
        return f
    bad = ~np.isfinite(f) | (f <= 0)
    if np.any(bad):
        raise ModelDomainError(f"{model}: load must be a positive number of newtons, got {f[bad].flat[0]!r} N")
    return f


def swing_stiffness_n_per_m(stiffness: Callable[[float], float], load_n: float, swing_n: float,
                            scale: float = 1.0) -> float:
    """Effective stiffness of a nonlinear contact k(F) whose force swings by ±ΔF about ``load_n`` (first order,
    amplitude-averaged over the decay): Δk/k = s·ΔF²·(k''/(8k) - k'²/(12k²)), k' and k'' derivatives in F by
    central differences (step 5 % of the load), s = 1/2 (energy weighting); ``scale`` multiplies the shift."""
    h = 0.05 * load_n
    k0, kp, km = (float(stiffness(x)) for x in (load_n, load_n + h, load_n - h))
    k_f, k_ff = (kp - km) / (2 * h), (kp - 2 * k0 + km) / h**2
    return k0 * (1.0 + scale * 0.5 * swing_n**2 * (k_ff / (8 * k0) - k_f**2 / (12 * k0**2)))
