"""Bounded least squares (``scipy.optimize.least_squares``, trust-region reflective) with a forward-difference
Jacobian: scipy's own ``'2-point'`` scheme at an absolute step of ``rel_step``·max(1, |x|).

The discrepancy fits have one to five parameters and a few hundred residuals: scipy's finite-difference driver
cost more than the residuals it differenced (its argument checks, bound preparation and wrappers run at every
iteration). This does the same arithmetic — the step turned back or shortened at a bound, the same columns in the
same memory layout — at about half the CPU. The step is not scipy's relative one (``diff_step``: ``rel_step``·|x|):
the fits' term parameters are scaled to a unit box (the depth, log10 of metres, has |x| ≥ 1 and keeps its step),
fits often start on its ends (the shape doubt starts the yield term's roughness exponent at 0), and least squares
moves such a start 10⁻¹⁰ inside, where a relative step of 10⁻¹⁶ changes residuals of order one by less than their
rounding. That column came out zero or noise, so whether the parameter ever left its end hung on the data's last
digits (the roughness exponent stayed at 0 or went to its optimum 0.04 as the stiffnesses moved by 10⁻⁹, the yield
term's probability 0.73 or 0.93: ``bench/discrepancy_stability.py``).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.optimize import OptimizeResult, least_squares


def forward_steps(x: np.ndarray, lo: np.ndarray, hi: np.ndarray, rel_step: float) -> np.ndarray:
    """Each parameter's step: ``rel_step`` × max(1, |x|) away from zero, reversed when it would leave the bounds
    and shortened to the distance to the farther bound when neither direction fits."""
    sign = (x >= 0).astype(float) * 2 - 1
    h = rel_step * sign * np.maximum(1.0, np.abs(x))
    below, above = x - lo, hi - x
    leaves = ((x + h) < lo) | ((x + h) > hi)
    fits = np.abs(h) <= np.maximum(below, above)
    h[leaves & fits] *= -1
    forward, backward = (above >= below) & ~fits, (above < below) & ~fits
    h[forward] = above[forward]
    h[backward] = -below[backward]
    return h


class ForwardJacobian:
    """``fun`` for least_squares, remembering its last value, and ``jac`` differencing from that value.

    least_squares asks for the Jacobian only at a point whose residuals it has just evaluated, so the value at
    the point is not computed again (it is, when it is not the remembered one)."""

    def __init__(self, fun: Callable[[np.ndarray], np.ndarray], lo: np.ndarray, hi: np.ndarray,
                 rel_step: float) -> None:
        self._fun, self._lo, self._hi, self._rel_step = fun, lo, hi, rel_step
        self._x: np.ndarray | None = None
        self._f: np.ndarray | None = None

    def fun(self, x: np.ndarray) -> np.ndarray:
        f = self._fun(x)
        self._x, self._f = x.copy(), f
        return f

    def jac(self, x: np.ndarray) -> np.ndarray:
        f0 = self._f if self._x is not None and np.array_equal(self._x, x) else self._fun(x)
        assert f0 is not None
        h = forward_steps(x, self._lo, self._hi, self._rel_step)
        columns = np.empty((x.size, f0.size))  # transposed, as scipy builds it: the same layout downstream
        for i in range(x.size):
            x1 = x.copy()
            x1[i] = x[i] + h[i]
            columns[i] = (self._fun(x1) - f0) / ((x[i] + h[i]) - x[i])
        return columns.T


def bounded_least_squares(fun: Callable[[np.ndarray], np.ndarray], x0: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                          *, ftol: float, xtol: float = 1e-6, rel_step: float = 1e-6,
                          max_nfev: int = 200) -> OptimizeResult:
    """``least_squares(fun, x0, bounds=(lo, hi), x_scale=1.0, …)`` with the Jacobian of ``ForwardJacobian``
    (scipy's '2-point' scheme at the absolute step ``rel_step``·max(1, |x|))."""
    fd = ForwardJacobian(fun, lo, hi, rel_step)
    return least_squares(fd.fun, x0, jac=fd.jac, bounds=(lo, hi), x_scale=1.0, xtol=xtol, ftol=ftol,
                         max_nfev=max_nfev)
