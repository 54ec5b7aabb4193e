"""The discrepancy fits' lean least squares: the same Jacobian and the same fit as scipy's own '2-point' scheme,
bit for bit, inside the bounds, on them and at zero."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares
from scipy.optimize._numdiff import approx_derivative

from labctl.discrepancy.lsq import ForwardJacobian, bounded_least_squares

LO, HI = np.array([-3.0, 0.0, 0.0, 0.0]), np.array([-1.0, 1.0, 1.0, 1.0])
T = np.linspace(0.0, 1.0, 40)


def residuals(x: np.ndarray) -> np.ndarray:
    """A smooth non-linear model with a kink-free exponential and a log, against fixed data."""
    model = 10.0 ** x[0] * np.exp(x[1] * T) + x[2] * np.log1p(T * (1 + 5 * x[3]))
    return model - (0.02 * np.exp(0.3 * T) + 0.4 * np.log1p(2 * T))


@pytest.mark.parametrize("x", [[-2.0, 0.5, 0.5, 0.5], [-3.0, 0.0, 1.0, 0.2], [-1.0, 1.0, 0.0, 1.0],
                               [-1.0 - 1e-9, 1.0 - 1e-12, 1e-300, 0.999999]])
def test_the_jacobian_is_scipys_2_point_scheme_bit_for_bit(x):
    x = np.array(x)
    fd = ForwardJacobian(residuals, LO, HI, 1e-6)
    mine = fd.jac(x)
    theirs = approx_derivative(residuals, x, method="2-point", rel_step=1e-6, bounds=(LO, HI))
    np.testing.assert_array_equal(mine, theirs)
    assert mine.flags.f_contiguous == theirs.flags.f_contiguous  # the same layout, so the same BLAS paths after


def test_the_fit_is_scipys_fit_bit_for_bit():
    x0 = np.array([-2.5, 0.9, 0.1, 0.9])
    mine = bounded_least_squares(residuals, x0, LO, HI, ftol=1e-8)
    theirs = least_squares(residuals, x0, bounds=(LO, HI), x_scale=1.0, diff_step=1e-6, xtol=1e-6, ftol=1e-8,
                           max_nfev=200)
    assert mine.nfev == theirs.nfev and mine.status == theirs.status
    np.testing.assert_array_equal(mine.x, theirs.x)
    np.testing.assert_array_equal(mine.fun, theirs.fun)
    assert np.sum(mine.fun**2) < 1e-3 * np.sum(residuals(x0) ** 2)  # it did fit
