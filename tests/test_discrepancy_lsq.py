"""The discrepancy fits' lean least squares: scipy's own '2-point' scheme at the absolute step
1e-6·max(1, |x|), bit for bit, inside the bounds, on them and at zero; and a parameter started on its bound is
differenced at a step its residuals feel, so it leaves the bound when its optimum is inside."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares
from scipy.optimize._numdiff import approx_derivative

from labctl.discrepancy.lsq import ForwardJacobian, bounded_least_squares

LO, HI = np.array([-3.0, 0.0, 0.0, 0.0]), np.array([-1.0, 1.0, 1.0, 1.0])
T = np.linspace(0.0, 1.0, 40)
REL_STEP = 1e-6


def residuals(x: np.ndarray) -> np.ndarray:
    """A smooth non-linear model with a kink-free exponential and a log, against fixed data."""
    model = 10.0 ** x[0] * np.exp(x[1] * T) + x[2] * np.log1p(T * (1 + 5 * x[3]))
    return model - (0.02 * np.exp(0.3 * T) + 0.4 * np.log1p(2 * T))


def scipy_jacobian(x: np.ndarray) -> np.ndarray:
    sign = (x >= 0).astype(float) * 2 - 1
    return approx_derivative(residuals, x, method="2-point", abs_step=REL_STEP * sign * np.maximum(1.0, np.abs(x)),
                             bounds=(LO, HI))


@pytest.mark.parametrize("x", [[-2.0, 0.5, 0.5, 0.5], [-3.0, 0.0, 1.0, 0.2], [-1.0, 1.0, 0.0, 1.0],
                               [-1.0 - 1e-9, 1.0 - 1e-12, 1e-300, 0.999999], [-2.0, 1e-10, 0.3, 1e-10]])
def test_the_jacobian_is_scipys_2_point_scheme_bit_for_bit(x):
    x = np.array(x)
    fd = ForwardJacobian(residuals, LO, HI, REL_STEP)
    mine = fd.jac(x)
    theirs = scipy_jacobian(x)
    np.testing.assert_array_equal(mine, theirs)
    assert mine.flags.f_contiguous == theirs.flags.f_contiguous  # the same layout, so the same BLAS paths after


def test_the_fit_is_scipys_fit_bit_for_bit():
    x0 = np.array([-2.5, 0.9, 0.1, 0.9])
    mine = bounded_least_squares(residuals, x0, LO, HI, ftol=1e-8)
    theirs = least_squares(residuals, x0, jac=scipy_jacobian, bounds=(LO, HI), x_scale=1.0, xtol=1e-6, ftol=1e-8,
                           max_nfev=200)
    assert mine.nfev == theirs.nfev and mine.status == theirs.status
    np.testing.assert_array_equal(mine.x, theirs.x)
    np.testing.assert_array_equal(mine.fun, theirs.fun)
    assert np.sum(mine.fun**2) < 1e-3 * np.sum(residuals(x0) ** 2)  # it did fit


@pytest.mark.parametrize("x", [0.0, 1e-10, 1e-6, 0.3])
def test_a_parameter_near_zero_is_differenced_at_a_step_its_residuals_feel(x):
    """Least squares moves a start on a bound 1e-10 inside it; a relative step (1e-16 there) changes residuals of
    order 1000 by less than their rounding, and the column came out zero or noise."""
    t = np.linspace(0.0, 1.0, 50)

    def big(v: np.ndarray) -> np.ndarray:
        return 1000.0 + v[0] * t**2

    column = ForwardJacobian(big, np.array([0.0]), np.array([1.0]), REL_STEP).jac(np.array([x]))[:, 0]
    np.testing.assert_allclose(column, t**2, atol=1e-6)


@pytest.mark.parametrize("level", [1.0, 30.0, 1000.0])
def test_a_fit_started_on_a_bound_reaches_an_optimum_inside_whatever_the_data_last_digits(level):
    """A shape parameter started at the end of its range (0) whose optimum is 0.04 must get there, and not stay at
    the bound on one draw of the rounding and leave it on the next."""
    t = np.linspace(0.0, 1.0, 200)
    lo, hi = np.array([0.0, 0.0]), np.array([10.0, 1.0])
    for shift in (0.0, 1e-13, 3e-13, 1e-12):
        y = level + 3.0 * np.exp(-t) + 0.04 * t + shift

        def fun(v: np.ndarray, y: np.ndarray = y) -> np.ndarray:
            return level + v[0] * np.exp(-t) + v[1] * t - y

        sol = bounded_least_squares(fun, np.array([1.0, 0.0]), lo, hi, ftol=1e-4)
        assert sol.x[1] == pytest.approx(0.04, abs=1e-3)
