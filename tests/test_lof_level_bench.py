"""The lack-of-fit level bench's split by the estimated noise: each campaign counted once per split, in its third."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from lof_level import SOURCES, by_noise  # noqa: E402


def test_rejections_gather_in_the_third_where_they_were_made():
    # steep σ(F) rejected at every level, flat never; the seating share carries no signal
    results = [(source, 0.5, 0.001 if steep > 2.0 else 0.9, steep, 0.3 + 0.1 * (i % 3))
               for source in SOURCES for i, steep in enumerate([1.0, 1.2, 1.4, 1.8, 1.9, 2.0, 2.5, 3.0, 3.5])]
    table = by_noise(results).splitlines()
    steep_rows = [row for row in table if "σ low / high load ≥" in row]
    flat_rows = [row for row in table if "σ low / high load <" in row]
    assert len(steep_rows) == len(flat_rows) == len(SOURCES)
    assert all(row.endswith("| 3 | 1.000 (3) | 1.000 (3) | 1.000 (3) |") for row in steep_rows)
    assert all(row.endswith("| 3 | 0.000 (0) | 0.000 (0) | 0.000 (0) |") for row in flat_rows)
    seat_rows = [row for row in table if "σ_seat / σ" in row]
    assert len(seat_rows) == 3 * len(SOURCES)
    assert sum(int(row.split("|")[3]) for row in seat_rows) == len(results)
