"""The outlier screen on the project's own simulated campaign: no clean point of the demo is set aside."""

from __future__ import annotations

from labctl.discrepancy import load_points
from labctl.discrepancy.set_aside import screened
from labctl.discrepancy.workflow import baseline_spec


def test_the_clean_demo_loses_no_point_to_the_outlier_screen(demo_campaign):
    # The twin's roughness bends ln k far more than the line contact does at its lowest loads, alike in its three
    # seatings. Lines drawn through ln k less Tripp's own curve (dd584a6, reverted) left that bend in, tightened
    # the band's scale and set a clean point of the lowest step aside (seating 2, 37.8 N).
    campaign, _ = demo_campaign  # labctl demo --json, run once for the session (tests/conftest.py)
    _, _, screening = screened(load_points([campaign]), baseline_spec("tripp"))
    assert screening.outliers == []
