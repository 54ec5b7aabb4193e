"""What a campaign's design leaves untested: too few roller geometries, one rail roughness, too few load steps.

Each limit says in words what the data cannot tell apart and which library terms it leaves without the dependence
that sets them apart from the rest. An explanation with such a term, alone or in a pair, is not named, whatever its
probability: the design cannot tell it from what the other candidates (or a look-alike outside the library) would
also give, so the verdict says which terms and why instead of naming them. Nor is a calibration or input error (a
measurement-side term, alone or with a physical one) named from stiffnesses alone: its source confirms it
(``AT_ITS_SOURCE``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from labctl.discrepancy.data import Dataset
from labctl.discrepancy.measurement import MEASUREMENT
from labctl.discrepancy.posterior import LIKELY_AT, NAME_AT, Explanation

LENGTH_SCALING = frozenset({"end_effects", "misalignment"})
"""Terms told from load-only ones by how they scale with roller length and diameter."""
RA_SCALING = frozenset({"surface_roughness"})
"""Terms told from a rig joint that closes with load only by their dependence on the rail's roughness."""
MIN_GEOMETRIES = 3
MIN_RAILS = 2
MIN_LOAD_STEPS = 5


@dataclass(frozen=True)
class DesignLimit:
    """One limit of the campaign's design: what it leaves untested, and the terms it leaves unseparated
    (``None``: every term)."""

    text: str
    terms: frozenset[str] | None
    pairs_only: bool = False
    """Holds back only pairs with one of its terms: a single term is still told from the others by its load law
    (the geometries' limit); the others hold back every explanation with one of their terms."""

    @property
    def short(self) -> str:
        """The limit in a few words ("one rail roughness")."""
        return self.text.partition(":")[0]

    def to_dict(self) -> dict[str, Any]:
        """The JSON form (``decision.design_limits``); a bench stores it to decide again as the workflow does."""
        return {"text": self.text, "terms": None if self.terms is None else sorted(self.terms),
                "pairs_only": self.pairs_only}

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> DesignLimit:
        """The limit a ``to_dict`` document holds (one written before ``pairs_only`` was stored: the geometries'
        limit, whose terms are the length-scaling ones, holds back pairs only, as it does now)."""
        terms = None if doc["terms"] is None else frozenset(doc["terms"])
        return cls(doc["text"], terms, doc.get("pairs_only", terms == LENGTH_SCALING))

    def covers(self, explanation: Explanation) -> bool:
        """Whether the explanation (a pair, where the limit holds back pairs only) rests on a term this limit holds
        back."""
        if len(explanation.terms) < (2 if self.pairs_only else 1):
            return False
        return self.terms is None or bool(self.terms & set(explanation.terms))


AT_ITS_SOURCE = DesignLimit(
    "a calibration or input error: confirmed at its source, not by stiffnesses alone (read the load cell at no load "
    "and against a reference load; check the Young's moduli given for roller and rail)", frozenset(MEASUREMENT))
"""Why a measurement-side term is held at "likely" whatever its probability: what imitates it in the stiffness (a
hard coating fading as the contact widens, a layer the library lacks) a direct check of the instrument or the
catalogue rules out, and an error named from the stiffness alone would be corrected into every later result."""


def design_limits(data: Dataset) -> list[DesignLimit]:
    """Why the data's design may not separate candidates (few geometries, one rail roughness, few loads)."""
    out = []
    geometries = len(data.roller_keys())
    if geometries < MIN_GEOMETRIES:
        out.append(DesignLimit(
            f"{geometries} roller geometr{'y' if geometries == 1 else 'ies'}: terms that differ by how they scale "
            "with length and diameter (end_effects, misalignment) cannot be told from load-only ones",
            LENGTH_SCALING, pairs_only=True))
    if len({round(c.case.rail_ra_m * 1e9) for c in data.cases}) < MIN_RAILS:
        out.append(DesignLimit(
            "one rail roughness: a term's dependence on Ra (surface_roughness, material_hardness) is not tested, "
            "and surface_roughness (an asperity compliance ∝ Ra/F in every contact, the same for every roller on "
            "one rail) cannot be told from a joint in the rig's load path whose compliance falls with load",
            RA_SCALING))
    steps = min(np.unique(np.round(np.log(c.load_n), 2)).size for c in data.cases)
    if steps < MIN_LOAD_STEPS:
        out.append(DesignLimit(f"{steps} load steps per roller: load laws cannot be told apart", None))
    return out


def unseparated(explanation: Explanation, limits: Sequence[DesignLimit]) -> DesignLimit | None:
    """What keeps the explanation from being named, if anything: the first design limit that leaves one of its
    terms unseparated, else a measurement-side term (``AT_ITS_SOURCE``)."""
    return next((limit for limit in [*limits, AT_ITS_SOURCE] if limit.covers(explanation)), None)


def not_named_words(explanation: Explanation, held: DesignLimit | None, fitted: dict[str, dict[str, float]]) -> str:
    """Why a likely explanation is not named, in words: the design limit that ``held`` it back, and for a
    measurement-side term the check at its source with its ``fitted`` value ("" when only its probability keeps it
    from a name)."""
    cannot = "separate its two terms" if len(explanation.terms) == 2 else \
        f"tell {explanation.name} from what acts like it"
    why = [] if held in (None, AT_ITS_SOURCE) else [f"{held.short}, so this design cannot {cannot} (below)"]
    if AT_ITS_SOURCE.covers(explanation):
        error, _, source = AT_ITS_SOURCE.text.partition(": ")
        values = ", ".join(f"{k} {v:.4g}" for term in fitted.values() for k, v in term.items())
        why.append(f"{error} is {source}" + (f"; fitted {values}" if values else ""))
    return "; ".join(why)


def decide(explanation: Explanation, probability: float, limits: Sequence[DesignLimit]) -> str:
    """What the verdict does with the most probable explanation: ``named`` at ≥ 0.9 unless a design limit holds
    one of its terms back or it has a measurement-side term (``unseparated``), ``likely`` from 0.5 (a held one too),
    else ``none``."""
    if not explanation.terms or probability < LIKELY_AT:
        return "none"
    if probability >= NAME_AT and unseparated(explanation, limits) is None:
        return "named"
    return "likely"
