"""The common shape of a contact model: stiffness (and deflection, where defined) vectorised over load."""

from __future__ import annotations

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
    bad = ~np.isfinite(f) | (f <= 0)
    if np.any(bad):
        raise ModelDomainError(f"{model}: load must be a positive number of newtons, got {f[bad].flat[0]!r} N")
    return f
