"""Physical effects the measured roller stiffness shows and Tripp lacks, as model terms.

Each effect transforms the stiffness of a baseline contact model for one contact case; its parameters are
physical, in SI, with bounds. The simulator hides them in its world and the discrepancy workflow fits them:
both use these classes, so each formula lives here once.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import ClassVar, Protocol, runtime_checkable

import numpy as np

from labctl.physics.catalogue import Roller
from labctl.physics.contact import FloatArray
from labctl.physics.materials import Material, effective_modulus, hardness_pa
from labctl.physics.rig import apparent_roller_stiffness
from labctl.physics.tripp import TrippContact

REFERENCE_RA_M = 0.2e-6
ROUGHNESS_REFERENCE_N_PER_M = 1e5
"""Load per length (100 N/mm) at which the roughness term's asperity scale is stated when its exponent is not 1."""


@dataclass(frozen=True)
class ContactCase:
    """One rolling element between one pair of rails: its geometry, materials and the rails' roughness."""

    roller: Roller
    rail: Material
    rail_ra_m: float

    @property
    def combined_ra_m(self) -> float:
        """Composite roughness of the two surfaces in contact."""
        ra = np.hypot(self.roller.roughness_ra_m, self.rail_ra_m)
        return float(ra) if np.ndim(ra) == 0 else ra

    @property
    def effective_modulus_pa(self) -> float:
        return effective_modulus(self.roller.material, self.rail)

    @property
    def softer_hardness_pa(self) -> float:
        """Indentation hardness of the softer of roller and rail (the body whose asperities yield first)."""
        return hardness_pa(np.minimum(self.roller.material.hardness_hrc, self.rail.hardness_hrc))

    def half_width_m(self, load_n: FloatArray) -> FloatArray:
        """Hertz line-contact half-width a at each load (Tripp's, which does not depend on the depth)."""
        return TrippContact(self.roller, self.rail).half_width_m(load_n)

    def peak_pressure_pa(self, load_n: FloatArray) -> FloatArray:
        """Hertz line-contact peak pressure p_max = sqrt(P·E*/(π·R))."""
        p = load_n / self.roller.contact_length_m
        return np.sqrt(p * self.effective_modulus_pa / (np.pi * self.roller.radius_m))


def stack_cases(cases: Sequence[ContactCase], sizes: Sequence[int]) -> ContactCase:
    """One case whose every property is a per-point array: ``sizes[i]`` points of ``cases[i]`` in a row.

    Every contact model and effect term is elementwise arithmetic on the case's properties, so a law evaluated on
    the stack gives the concatenation of its values on each case (to the last bit, but for NumPy's vectorised
    powers: one ulp), in one call instead of one per case: the discrepancy fits evaluate laws thousands of times."""

    def each(get: Callable[[ContactCase], float]) -> np.ndarray:
        return np.repeat(np.array([get(c) for c in cases], dtype=float), sizes)

    def material(get: Callable[[ContactCase], Material]) -> Material:
        return Material("stacked", each(lambda c: get(c).youngs_modulus_pa), each(lambda c: get(c).poisson_ratio),
                        each(lambda c: get(c).hardness_hrc))

    roller = Roller(each(lambda c: c.roller.diameter_m), each(lambda c: c.roller.contact_length_m),
                    each(lambda c: c.roller.total_length_m), material(lambda c: c.roller.material),
                    each(lambda c: c.roller.roughness_ra_m))
    return ContactCase(roller, material(lambda c: c.rail), each(lambda c: c.rail_ra_m))


@runtime_checkable
class Effect(Protocol):
    """A model term: maps the stiffness without the effect to the stiffness with it."""

    name: ClassVar[str]
    BOUNDS: ClassVar[dict[str, tuple[float, float]]]

    def apply(self, case: ContactCase, load_n: FloatArray, stiffness_n_per_m: FloatArray) -> FloatArray: ...

    def parameters(self) -> dict[str, float]: ...


class BoundedParams:
    """Mixin of a model term with bounded parameters: ``parameters()`` are its ``BOUNDS`` keys with their values."""

    LOOK_ALIKE: ClassVar[str] = ""
    """What else gives the term's signature, where the physics has a look-alike: a verdict that names the term, or
    finds it likely, says so."""

    def parameters(self) -> dict[str, float]:
        return {k: float(getattr(self, k)) for k in self.BOUNDS}  # type: ignore[attr-defined]


@dataclass(frozen=True)
class SurfaceRoughness(BoundedParams):
    """Asperity compliance in series with each of the two contacts.

    An exponential asperity-height tail makes the asperity layer's stiffness proportional to load,
    k_asp = F/σ_s, with σ_s = asperity_scale·Ra (composite roller/rail Ra): strongest at low load, grows
    with roughness, independent of diameter. Other height distributions stiffen more slowly: ``load_exponent``
    m makes k_asp ∝ F·(p/p_ref)^(m−1) with p = F/L_we and p_ref = 100 N/mm (m = 1 the exponential tail; a
    Gaussian tail, or a layer of height ~Ra squeezed across the contact width, behaves as m ≈ ½). m is not a
    world parameter (not in ``BOUNDS``); the discrepancy fit frees it, so a rough layer that stiffens more
    slowly than the exponential tail is not taken for another effect.
    """

    asperity_scale: float = 1.3
    load_exponent: float = 1.0
    name: ClassVar[str] = "surface_roughness"
    BOUNDS: ClassVar[dict[str, tuple[float, float]]] = {"asperity_scale": (0.0, 20.0)}
    LOOK_ALIKE: ClassVar[str] = ("any other compliant layer on the surfaces that closes with load (an oxide, a porous "
                                 "or lubricant film)")

    def apply(self, case: ContactCase, load_n: FloatArray, stiffness_n_per_m: FloatArray) -> FloatArray:
        compliance = 2.0 * self.asperity_scale * case.combined_ra_m / load_n
        if self.load_exponent != 1.0:
            compliance = compliance * (load_n / case.roller.contact_length_m / ROUGHNESS_REFERENCE_N_PER_M) ** (
                1.0 - self.load_exponent)
        return 1.0 / (1.0 / stiffness_n_per_m + compliance)


@dataclass(frozen=True)
class EndEffects(BoundedParams):
    """The rail material beyond each roller end carries load too: an extra effective length at each end.

    k = k_line·(1 + 2·edge/L_we): stiffness per length falls with roller length. The edge is ``edge_length_m``
    plus ``half_width_share`` κ times the contact half-width a: an end's stress field reaches about a half-width
    beyond it, so the zone the ends add (or lose) may grow with load; plus ``radius_share`` ψ times the roller
    radius R, an end profile or chamfer cut in proportion to the roller. κ and ψ are not world parameters (not in
    ``BOUNDS``); the discrepancy fit frees them, so ends that engage with load or scale with the roller are not
    taken for another effect.
    """

    edge_length_m: float = 0.1e-3
    half_width_share: float = 0.0
    radius_share: float = 0.0
    name: ClassVar[str] = "end_effects"
    BOUNDS: ClassVar[dict[str, tuple[float, float]]] = {"edge_length_m": (0.0, 2e-3)}

    def apply(self, case: ContactCase, load_n: FloatArray, stiffness_n_per_m: FloatArray) -> FloatArray:
        edge = self.edge_length_m
        if self.half_width_share:
            edge = edge + self.half_width_share * case.half_width_m(load_n)
        if self.radius_share:
            edge = edge + self.radius_share * case.roller.radius_m
        return stiffness_n_per_m * (1.0 + 2.0 * edge / case.roller.contact_length_m)


@dataclass(frozen=True)
class MaterialHardness(BoundedParams):
    """Plastic conformity: once p_max exceeds a fraction of the softer body's hardness, its asperities yield
    and conform to the rail's roughness, adding contact area and stiffness.

    k = k_in·(1 + gain·(Ra/0.2 µm)^α·max(0, p_max/(threshold·H) - 1)): rises with load, larger for softer
    rollers and rougher rails. ``roughness_exponent`` α = 1 is asperity conformity (the added area scales with
    the roughness it fills); α = 0 is yield of the softer body's bulk, which depends on its hardness, not on
    the surface. It is not a world parameter (not in ``BOUNDS``); the discrepancy fit frees it, so a yield
    that does not follow the rail's roughness is not mistaken for an effect outside the library.
    """

    gain: float = 0.15
    threshold: float = 0.3
    roughness_exponent: float = 1.0
    name: ClassVar[str] = "material_hardness"
    BOUNDS: ClassVar[dict[str, tuple[float, float]]] = {"gain": (0.0, 2.0), "threshold": (0.05, 1.0)}
    KINK: ClassVar[str] = "threshold"
    """The parameter that places the term's kink in k(F) (the onset load)."""

    def apply(self, case: ContactCase, load_n: FloatArray, stiffness_n_per_m: FloatArray) -> FloatArray:
        yield_pa = self.threshold * case.softer_hardness_pa
        excess = np.maximum(0.0, case.peak_pressure_pa(load_n) / yield_pa - 1.0)
        roughness = (case.combined_ra_m / REFERENCE_RA_M) ** self.roughness_exponent
        return stiffness_n_per_m * (1.0 + self.gain * roughness * excess)


@dataclass(frozen=True)
class Misalignment(BoundedParams):
    """A roller tilted by a small angle against the rail touches along only part of its length at first.

    With a linear gap γ·x and stiffness per length k' = k/L_we, the contact length grows as
    L_c = sqrt(2F/(k'γ)) until it reaches L_we: k = k_full·min(1, L_c/L_we). Strongly length dependent.

    That kink is the independent-spring (Winkler) picture. On an elastic body the load spreads beyond the
    touching part and the last part of the length closes gradually, so the transition is rounded: ``transition``
    w > 0 replaces min(1, x) by the generalised-mean soft minimum (1 + x^(−1/w))^(−w) (w → 0: the kink). It is not
    a world parameter (not in ``BOUNDS``); the discrepancy fit frees it so a real tilt law's rounding is not
    mistaken for another effect.
    """

    tilt_rad: float = 2e-4
    transition: float = 0.0
    name: ClassVar[str] = "misalignment"
    BOUNDS: ClassVar[dict[str, tuple[float, float]]] = {"tilt_rad": (0.0, 5e-3)}

    def apply(self, case: ContactCase, load_n: FloatArray, stiffness_n_per_m: FloatArray) -> FloatArray:
        if self.tilt_rad <= 0:
            return stiffness_n_per_m
        length = case.roller.contact_length_m
        per_length = stiffness_n_per_m / length
        contact_length = np.sqrt(2.0 * load_n / (per_length * self.tilt_rad))
        if self.transition <= 0:
            return stiffness_n_per_m * np.minimum(1.0, contact_length / length)
        w = self.transition
        ln_x = np.log(contact_length / length)
        return stiffness_n_per_m * np.exp(-w * np.logaddexp(0.0, -ln_x / w))


@dataclass(frozen=True)
class SetupCompliance(BoundedParams):
    """The rig's true K_setup differs from the nominal value the processing assumes (e.g. stress stiffening).

    The reported roller stiffness is then 1/(1/k + 3/(factor·K) - 3/K) (Eq. 4): the error grows with k.
    """

    stiffness_factor: float = 1.25
    nominal_setup_n_per_m: float = 1.45e9
    name: ClassVar[str] = "setup_compliance"
    LOOK_ALIKE: ClassVar[str] = ("a compliant layer under the rails (a shim or a bonded base), which spreads "
                                 "each roller's load over its length plus the layer's depth, so every roller loads it "
                                 "nearly alike")
    RIG_LEVEL: ClassVar[bool] = True
    """A property of the rig, not of the roller: one stiffness factor for every roller measured on it at a given
    load (a joint in the load path may stiffen with load, so rollers are compared at the loads they share)."""
    BOUNDS: ClassVar[dict[str, tuple[float, float]]] = {"stiffness_factor": (0.3, 5.0)}

    def apply(self, case: ContactCase, load_n: FloatArray, stiffness_n_per_m: FloatArray) -> FloatArray:
        return apparent_roller_stiffness(
            stiffness_n_per_m, self.stiffness_factor * self.nominal_setup_n_per_m, self.nominal_setup_n_per_m
        )


EFFECTS: dict[str, type] = {
    cls.name: cls for cls in (SurfaceRoughness, EndEffects, MaterialHardness, Misalignment, SetupCompliance)
}
