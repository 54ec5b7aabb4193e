"""True contact laws a world may hide that are not terms of the discrepancy library (``labctl.physics.effects``).

- ``ConformingContact``: the default world's physics — Tripp's line contact with end effects, in series with an
  asperity layer that the softer body flattens plastically once the contact pressure nears its hardness
  (plastic conformity: softer rollers stiffen on rough rails, much less on smooth ones).
- ``TabulatedLaw``: a measured k(F) per roller type, interpolated in log-log.
- ``ExpressionLaw``: k as an expression in F, L, D, E*, Ra, hardness, parsed with ``ast`` and evaluated from a
  whitelist (numbers, fixed names, + - * / **, a few functions): no code from a world file ever runs.

Each law is a frozen dataclass with ``stiffness_n_per_m(case, load_n)``; library effects may follow it.
"""

from __future__ import annotations

import ast
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from labctl.physics.contact import FloatArray, as_load
from labctl.physics.effects import REFERENCE_RA_M, ContactCase, Effect
from labctl.physics.tripp import TrippContact

SPOT_AREA_M2 = 0.01e-6  # reference contact patch of the seating scatter


@dataclass(frozen=True)
class ConformingContact:
    """Elastic line contact with end effects, in series with a plastically conforming asperity layer.

    1/k = 1/(k_Tripp(t)·(1 + 2·edge/L_we)·(1 + b·(L_r - L_we)/L_we)) + 2·σ_eff/F.
    End effects: edge = edge_length + edge_half_widths·a (the rail beyond each end carries load over a zone as
    deep as the contact's stress field, ∝ the half-width a). Asperity layer (exponential height tail, stiffness
    F/σ per contact): σ = asperity_scale·sqrt(Ra_rail² + (roller_ra_weight·Ra_roller)²); the softer body's
    asperities yield as the peak Hertz pressure p approaches a fraction of its hardness H:
    σ_eff = σ / (1 + (p/(conformity·H))^n). Bedding b: see ``bedded_fraction``. Lower hardness → more
    conformity → stiffer, most on rough rails.
    """

    depth_m: float = 1.6e-3
    edge_length_m: float = 0.0
    edge_half_widths: float = 0.0
    asperity_scale: float = 1.4
    roller_ra_weight: float = 0.5
    conformity: float = 0.45
    conformity_exponent: float = 2.0
    bedding: float = 0.42
    bedding_exponent: float = 10.0
    asperity_spot_rel: float = 0.0
    seating_z: float = 0.0  # this seating's draw (standard normal, set by ``reseated``; not a world-file key)
    name: ClassVar[str] = "conforming"
    BOUNDS: ClassVar[dict[str, tuple[float, float]]] = {
        "depth_m": (1e-4, 0.1), "edge_length_m": (0.0, 2e-3),
        "edge_half_widths": (0.0, 20.0), "asperity_scale": (0.0, 20.0),
        "roller_ra_weight": (0.0, 1.0), "conformity": (0.01, 10.0),
        "conformity_exponent": (0.5, 20.0), "bedding": (0.01, 10.0), "bedding_exponent": (0.5, 40.0),
        "asperity_spot_rel": (0.0, 2.0),
    }

    def reseated(self, rng: np.random.Generator) -> ConformingContact:
        """The same contact on a new spot of roller and rail: a new draw of the asperities it happens to meet."""
        return replace(self, seating_z=float(rng.standard_normal()))

    def asperity_height_m(self, case: ContactCase, load_n: FloatArray) -> FloatArray:
        """Asperity layer height on this seating's contact spot. The spot samples few asperities while the
        contact patch 2a·L_we is small, so its height scatters by asperity_spot_rel·sqrt(A_ref/A) (A_ref
        0.01 mm²) from seating to seating: large at low load, small at high load."""
        nominal = self.asperity_scale * math.hypot(case.rail_ra_m, self.roller_ra_weight * case.roller.roughness_ra_m)
        if self.asperity_spot_rel == 0.0 or self.seating_z == 0.0:
            return np.full_like(load_n, nominal)
        half_width = TrippContact(case.roller, case.rail, self.depth_m).half_width_m(load_n)
        patch = 2.0 * half_width * case.roller.contact_length_m
        return nominal * np.exp(self.asperity_spot_rel * self.seating_z * np.sqrt(SPOT_AREA_M2 / patch))

    def conformity_factor(self, case: ContactCase, load_n: FloatArray) -> FloatArray:
        """σ_eff/σ: 1 while the contact is elastic, falling as the peak pressure nears the softer body's hardness."""
        return 1.0 / (1.0 + (case.peak_pressure_pa(load_n) / (self.conformity * case.softer_hardness_pa))
                      ** self.conformity_exponent)

    def bedded_fraction(self, case: ContactCase, load_n: FloatArray) -> FloatArray:
        """Share of the roller's profiled ends (L_r - L_we) bedded in plastically: the asperity pressures, higher
        on rougher rails, reach the softer body's hardness first at the ends, so the bearing length grows."""
        x = (case.peak_pressure_pa(load_n) / (self.bedding * case.softer_hardness_pa)) ** self.bedding_exponent
        return min(1.0, case.combined_ra_m / REFERENCE_RA_M) * x / (1.0 + x)

    def stiffness_n_per_m(self, case: ContactCase, load_n: ArrayLike) -> FloatArray:
        f = as_load(load_n, self.name)
        r = case.roller
        tripp = TrippContact(r, case.rail, self.depth_m)
        bulk = tripp.stiffness_n_per_m(f)
        ends = max(0.0, r.total_length_m - r.contact_length_m) / r.contact_length_m
        edge = self.edge_length_m + self.edge_half_widths * tripp.half_width_m(f)
        bulk = bulk * (1.0 + 2.0 * edge / r.contact_length_m)
        bulk = bulk * (1.0 + ends * self.bedded_fraction(case, f))
        layer = 2.0 * self.asperity_height_m(case, f) * self.conformity_factor(case, f) / f
        return 1.0 / (1.0 / bulk + layer)


@dataclass(frozen=True)
class TabulatedLaw:
    """Measured stiffness per roller type: (loads, stiffnesses) interpolated log-log, extrapolated at the ends'
    slopes. A roller type without a table is refused (the world cannot say what it is)."""

    tables: tuple[tuple[int, tuple[float, ...], tuple[float, ...]], ...]
    name: ClassVar[str] = "table"
    BOUNDS: ClassVar[dict[str, tuple[float, float]]] = {}

    def stiffness_n_per_m(self, case: ContactCase, load_n: ArrayLike) -> FloatArray:
        f = as_load(load_n, self.name)
        for type_id, loads, ks in self.tables:
            if type_id == case.roller.type_id:
                x, y = np.log(loads), np.log(ks)
                lf = np.log(f)
                inside = np.interp(lf, x, y)
                lo = y[0] + (y[1] - y[0]) / (x[1] - x[0]) * (lf - x[0])
                hi = y[-1] + (y[-1] - y[-2]) / (x[-1] - x[-2]) * (lf - x[-1])
                return np.exp(np.where(lf < x[0], lo, np.where(lf > x[-1], hi, inside)))
        known = ", ".join(str(t[0]) for t in self.tables)
        raise ValueError(f"table law: no table for roller type {case.roller.type_id}; the world has {known}")


EXPRESSION_FUNCTIONS: dict[str, Callable[..., Any]] = {
    "log": np.log, "exp": np.exp, "sqrt": np.sqrt, "tanh": np.tanh, "abs": np.abs, "minimum": np.minimum,
    "maximum": np.maximum,
}
ARITY = {"minimum": 2, "maximum": 2}  # the others take one argument
EXPRESSION_NAMES = {
    "F": "load per roller (N)", "L": "contact length L_we (m)", "Lr": "total roller length L_r (m)",
    "D": "roller diameter (m)", "R": "roller radius (m)", "E": "effective modulus E* (Pa)",
    "Ra": "composite roughness (m)", "Ra_rail": "rail roughness (m)", "H": "hardness of the softer body (Pa)",
    "pi": "π",
}
_BINARY: dict[type, Callable[[Any, Any], Any]] = {
    ast.Add: np.add, ast.Sub: np.subtract, ast.Mult: np.multiply, ast.Div: np.divide, ast.Pow: np.power,
}


MAX_EXPRESSION_CHARS = 2000
MAX_EXPRESSION_NODES = 400
MAX_EXPRESSION_DEPTH = 40
MAX_CONSTANT = 1e100
"""Bounds of a world expression: text length, syntax-tree size and depth, constants' magnitude. A contact
law is a line or two of arithmetic; these keep parsing and evaluating small and the numbers finite."""
STIFFNESS_RANGE_N_PER_M = (1e3, 1e13)
"""Stiffness a world law may give a roller: far wider than any steel contact (about 1e7 to 1e10 N/m), narrow
enough that the rig's modes stay finite numbers."""


def _depth(tree: ast.AST) -> int:
    deepest, stack = 0, [(tree, 1)]
    while stack:
        node, d = stack.pop()
        deepest = max(deepest, d)
        stack.extend((child, d + 1) for child in ast.iter_child_nodes(node))
    return deepest


def check_expression(text: str) -> ast.Expression:
    """Parse ``text`` and refuse anything but numbers, the fixed names, + - * / **, unary ± and the functions,
    and anything beyond the bounds above (a ValueError saying which)."""
    if len(text) > MAX_EXPRESSION_CHARS:
        raise ValueError(f"{len(text)} characters, more than the {MAX_EXPRESSION_CHARS} an expression may have")
    try:
        tree = ast.parse(text, mode="eval")
    except SyntaxError as exc:
        raise ValueError(f"not an expression: {exc.msg}") from None
    except (RecursionError, MemoryError):
        raise ValueError(f"nested too deeply (at most {MAX_EXPRESSION_DEPTH} levels)") from None
    nodes = sum(1 for _ in ast.walk(tree))
    if nodes > MAX_EXPRESSION_NODES:
        raise ValueError(f"{nodes} terms and operators, more than the {MAX_EXPRESSION_NODES} an expression may have")
    if _depth(tree) > MAX_EXPRESSION_DEPTH:
        raise ValueError(f"nested more than {MAX_EXPRESSION_DEPTH} levels deep")
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, int | float) and not isinstance(node.value, bool):
            if isinstance(node.value, int) and node.value.bit_length() > 400:
                raise ValueError(f"the integer {str(node.value)[:12]}… is too large (at most {MAX_CONSTANT:g})")
            if not abs(float(node.value)) <= MAX_CONSTANT:
                raise ValueError(f"the number {node.value:.6g} is out of range (at most {MAX_CONSTANT:g})")
    callees = {id(n.func) for n in ast.walk(tree) if isinstance(n, ast.Call)}
    for node in ast.walk(tree):
        if isinstance(node, (ast.Expression, ast.Load)) or type(node) in _BINARY:
            continue
        if isinstance(node, ast.BinOp | ast.UnaryOp) and (
            type(getattr(node, "op", None)) in _BINARY or isinstance(node.op, ast.USub | ast.UAdd)
        ):
            continue
        if isinstance(node, ast.USub | ast.UAdd):
            continue
        if isinstance(node, ast.Constant) and isinstance(node.value, int | float) and not isinstance(node.value, bool):
            continue
        if isinstance(node, ast.Name) and (
            node.id in EXPRESSION_NAMES or (node.id in EXPRESSION_FUNCTIONS and id(node) in callees)
        ):
            continue
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in EXPRESSION_FUNCTIONS
                and not node.keywords):
            if len(node.args) != ARITY.get(node.func.id, 1) or any(isinstance(a, ast.Starred) for a in node.args):
                raise ValueError(f"{node.func.id}() takes {ARITY.get(node.func.id, 1)} argument(s)")
            continue
        what = (node.id if isinstance(node, ast.Name)
                else node.func.id if isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
                else type(node).__name__)
        raise ValueError(
            f"{what!r} is not allowed; use numbers, + - * / **, the names {', '.join(EXPRESSION_NAMES)} and the "
            f"functions {', '.join(EXPRESSION_FUNCTIONS)}"
        )
    return tree


def _evaluate(node: ast.AST, env: Mapping[str, Any]) -> Any:
    if isinstance(node, ast.Expression):
        return _evaluate(node.body, env)
    if isinstance(node, ast.Constant):
        return float(node.value)
    if isinstance(node, ast.Name):
        return env[node.id]
    if isinstance(node, ast.BinOp):
        return _BINARY[type(node.op)](_evaluate(node.left, env), _evaluate(node.right, env))
    if isinstance(node, ast.UnaryOp):
        value = _evaluate(node.operand, env)
        return -value if isinstance(node.op, ast.USub) else value
    if isinstance(node, ast.Call):
        assert isinstance(node.func, ast.Name)
        return EXPRESSION_FUNCTIONS[node.func.id](*(_evaluate(a, env) for a in node.args))
    raise ValueError(f"unexpected {type(node).__name__}")  # check_expression refuses it first


@dataclass(frozen=True)
class ExpressionLaw:
    """k(F) from a whitelisted arithmetic expression (see ``EXPRESSION_NAMES``); the result must be > 0."""

    expression: str
    name: ClassVar[str] = "expression"
    BOUNDS: ClassVar[dict[str, tuple[float, float]]] = {}

    def __post_init__(self) -> None:
        check_expression(self.expression)

    def stiffness_n_per_m(self, case: ContactCase, load_n: ArrayLike) -> FloatArray:
        f = as_load(load_n, self.name)
        r = case.roller
        env = {"F": f, "L": r.contact_length_m, "Lr": r.total_length_m, "D": r.diameter_m, "R": r.radius_m,
               "E": case.effective_modulus_pa, "Ra": case.combined_ra_m, "Ra_rail": case.rail_ra_m,
               "H": case.softer_hardness_pa, "pi": math.pi}
        with np.errstate(all="ignore"):
            k = np.broadcast_to(np.asarray(_evaluate(check_expression(self.expression), env), dtype=float), f.shape)
        if not np.all(np.isfinite(k) & (k > 0)):
            raise ValueError(f"expression {self.expression!r} gives a non-positive or non-finite stiffness "
                             f"for roller type {r.type_id} between {f.min():g} and {f.max():g} N")
        return np.array(k, dtype=float)


@dataclass(frozen=True)
class WorldLaw:
    """A world's own baseline (one of the laws above) followed by library effect terms, like ``ContactLaw``."""

    base: ConformingContact | TabulatedLaw | ExpressionLaw
    effects: tuple[Effect, ...] = field(default=())

    @property
    def baseline(self) -> str:
        return self.base.name

    def stiffness_n_per_m(self, case: ContactCase, load_n: ArrayLike) -> FloatArray:
        """The law's stiffness; a value outside ``STIFFNESS_RANGE_N_PER_M`` (or not finite) is a ValueError
        naming the law, the roller type and the loads, not a number the rig model cannot use."""
        f = as_load(load_n, self.base.name)
        k = np.asarray(self.base.stiffness_n_per_m(case, f), dtype=float)
        for effect in self.effects:
            k = effect.apply(case, f, k)
        lo, hi = STIFFNESS_RANGE_N_PER_M
        with np.errstate(invalid="ignore"):
            bad = ~(np.isfinite(k) & (k >= lo) & (k <= hi))
        if np.any(bad):
            at = np.broadcast_to(f, np.shape(k))[bad]
            raise ValueError(f"world law {self.base.name!r} gives a stiffness of {np.asarray(k)[bad].flat[0]:.4g} N/m "
                             f"for roller type {case.roller.type_id} at {at.min():g} N; expected {lo:g} to "
                             f"{hi:g} N/m (check the law's numbers and the loads it covers)")
        return k

    @property
    def effect_names(self) -> tuple[str, ...]:
        return tuple(e.name for e in self.effects)

    def with_base(self, **changes: float) -> WorldLaw:
        return replace(self, base=replace(self.base, **changes))  # type: ignore[type-var]


WORLD_BASELINES: dict[str, type] = {cls.name: cls for cls in (ConformingContact, TabulatedLaw, ExpressionLaw)}
