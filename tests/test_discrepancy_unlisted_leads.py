"""The evaluation bench's count of "unlisted" leads: which were a library effect, and whether the closest library
term the verdict named was one of the truth's terms."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from discrepancy_features import unlisted_leads  # noqa: E402


def record(top, p, closest, effects=(), measurement=(), outside=False, scenario="s"):
    return {"top": top, "top_probability": p, "closest": closest, "truth_effects": list(effects),
            "truth_measurement": list(measurement), "outside_library": outside, "scenario": scenario}


def test_unlisted_leads_counts_library_truths_and_closest_terms():
    results = [record("unlisted", 0.95, "surface_roughness", ["surface_roughness", "end_effects"]),
               record("unlisted", 0.6, "material_hardness", ["surface_roughness"]),
               record("unlisted", 0.99, "end_effects", outside=True, scenario="outside_rate_dependence"),
               record("unlisted", 0.4, "end_effects", ["end_effects"]),  # below the threshold
               record("end_effects", 0.95, None, ["end_effects"])]  # not an unlisted lead
    assert unlisted_leads(results) == (
        "\"unlisted\" top at ≥ 0.5: 3 datasets; a library truth 2 (the closest library term one of its terms in 1), "
        "an effect outside the library 1 (closest: outside_rate_dependence → end_effects 1)")
    assert "top at ≥ 0.9: 2 datasets; a library truth 1 (the closest library term one of its terms in 1)" in \
        unlisted_leads(results, 0.9)
