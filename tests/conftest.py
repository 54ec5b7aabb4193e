"""Fixtures shared by test modules."""

from __future__ import annotations

import pytest

from drivers.sim import RigTwin


@pytest.fixture
def first_blow_double(monkeypatch):
    """The campaign's first blow is a double hit (a second pulse 100 ms later, 10 % as strong)."""
    original, blows = RigTwin.strike, []

    def strike(self: RigTwin):  # noqa: ANN202
        blows.append(1)
        if len(blows) == 1:
            self.next_blow_double(delay_s=0.1, ratio=0.1)
        return original(self)

    monkeypatch.setattr(RigTwin, "strike", strike)
    return blows
