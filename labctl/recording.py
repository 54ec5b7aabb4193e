"""Storing a step's identification and a repetition's stiffness curve: one way, used by the engine and imports."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from labctl.processing import Identification
from labctl.storage import schema
from labctl.storage.writer import CampaignWriter

CURVE_COLUMNS = ("load_n", "stiffness_n_per_m", "stiffness_std_n_per_m", "bounce_hz", "bounce_damping_ratio",
                 "tilt_a_hz", "tilt_b_hz", "coherence_at_bounce", "knob_angle_deg")


def store_step_result(writer: CampaignWriter, series: int, run: int, step: int, result: Identification | str,
                      attempts: Sequence[int]) -> None:
    """Store a step's identification (impacts numbered by their attempts), or mark the step failed with why."""
    if isinstance(result, str):
        writer.update_step(series, run, step, {"failed": result, schema.COMPLETE: True})
        return
    summary = result.to_dict()
    summary["impacts"] = [{**imp, "attempt": attempts[i]} for i, imp in enumerate(summary.get("impacts", []))]
    writer.write_step_result(series, run, step, summary, result.frequencies_hz, result.h1, result.coherence)


def store_curve(writer: CampaignWriter, series: int, run: int) -> dict[str, np.ndarray]:
    """Build the repetition's stiffness-vs-load table from its stored step results, store it, and return it."""
    rg = writer.h5[schema.series_name(series)][schema.run_name(run)]
    rows = []
    for name in sorted(k for k in rg if k.startswith("step_")):
        g = rg[name]
        res = g.get(schema.RESULT)
        if res is None or not res.attrs.get(schema.COMPLETE):
            continue
        tilt = np.asarray(res.attrs.get("tilt_hz", [np.nan, np.nan]), dtype=float).ravel()
        tilt = tilt if tilt.size >= 2 else np.array([np.nan, np.nan])
        a = res.attrs
        rows.append((float(g.attrs["load_n"]), float(a["roller_stiffness_n_per_m"]),
                     float(a.get("roller_stiffness_std_n_per_m", np.nan)), float(a["bounce_hz"]),
                     float(a.get("bounce_damping_ratio", np.nan)), tilt[0], tilt[1],
                     float(a.get("coherence_at_bounce", np.nan)), float(g.attrs.get("knob_angle_deg", np.nan))))
    table = {c: np.array([r[i] for r in rows], dtype=float) for i, c in enumerate(CURVE_COLUMNS)}
    writer.write_curve(series, run, table)
    return table
