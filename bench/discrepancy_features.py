"""Which physical quantities the "unlisted" stand-in's features carry, by the blind truth; and what the truth was
where "unlisted" led, beside the library term the verdict called closest.

The stand-in for an effect outside the library is the baseline plus up to three features of the empirical basis
(``labctl.discrepancy.empirical.BASIS``). Some features carry a quantity a library term is named for: the composite
roughness Ra (surface_roughness, and material_hardness's conformity), the peak pressure over the hardness
(material_hardness), the roller's contact length (end_effects, misalignment). If outside-library effects were
described without them and library effects with them, "unlisted" could be read as a library term in a foreign
form; this table shows whether the blind worlds allow that. Used by ``bench/discrepancy_eval.py``.

Where "unlisted" leads the verdict names the single library term that alone takes up most of the misfit
(``labctl.discrepancy.caveats``) and says the lead may be that term in another law: ``unlisted_leads`` counts how
often the truth was a library effect, and how often that term was one of its terms.
"""

from __future__ import annotations

from collections import Counter
from typing import Any

QUANTITY = {
    "Ra/Ra0": "Ra", "(Ra/Ra0)·(p/p0)^-1": "Ra",
    "p_max/H": "p_max/H", "(p_max/H)^2": "p_max/H",
    "ln(L/L0)": "length", "(L/L0)^-1": "length", "(L/L0)^-1·(p/p0)^-0.5": "length", "(L/L0)^-1·ln(p/p0)": "length",
}
"""Feature → the library quantity it carries (features absent here carry only the load, diameter or modulus)."""
COLUMNS = ("Ra", "p_max/H", "length", "load, D or E* only", "none stored")


def carried(features: list[str] | None) -> str:
    """The column a stand-in's feature list falls in: the first library quantity among its features."""
    if features is None:
        return "none stored"
    found = [QUANTITY[f] for f in features if f in QUANTITY]
    return found[0] if found else "load, D or E* only"


def kind(r: dict[str, Any]) -> str:
    """The blind truth's kind: a single term by name, or a pair, calibration error, outside effect, none."""
    t = r["truth_name"]
    if t == "unlisted":
        return "outside the library"
    if " + " in t:
        return "pair"
    return t


def features_by_truth(results: list[dict[str, Any]]) -> str:
    """A table: for each kind of truth, how many stand-ins carry each quantity (first one found)."""
    counts: dict[str, Counter[str]] = {}
    for r in results:
        stand_in = next((c for c in r.get("candidates", []) if c["explanation"] == "unlisted"), None)
        feats = stand_in.get("features") if stand_in else None
        counts.setdefault(kind(r), Counter())[carried(feats)] += 1
    lines = ["| truth | n | " + " | ".join(COLUMNS) + " |", "|---|---|" + "---|" * len(COLUMNS)]
    for k in sorted(counts):
        c = counts[k]
        lines.append(f"| {k} | {sum(c.values())} | " + " | ".join(str(c[col]) for col in COLUMNS) + " |")
    return "\n".join(lines)


def unlisted_leads(results: list[dict[str, Any]], at: float = 0.5) -> str:
    """Where "unlisted" is the top explanation at ≥ ``at``: library truths (the closest term one of the truth's),
    effects outside the library, and the closest term most often named for each (stored as ``closest``)."""
    led = [r for r in results if r["top"] == "unlisted" and r["top_probability"] >= at and "closest" in r]
    lib = [r for r in led if not r["outside_library"]]
    hit = sum(r["closest"] in [*r["truth_effects"], *r["truth_measurement"]] for r in lib)
    common = Counter(f"{r['scenario']} → {r['closest']}" for r in led if r["outside_library"]).most_common(4)
    return (f"\"unlisted\" top at ≥ {at:g}: {len(led)} datasets; a library truth {len(lib)} (the closest library "
            f"term one of its terms in {hit}), an effect outside the library {len(led) - len(lib)} (closest: "
            + (", ".join(f"{k} {v}" for k, v in common) or "-") + ")")
