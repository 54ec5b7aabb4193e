"""The accelerometers' cross-axis coupling on a mode's constants: each axis picks up a little of its sensor's two
others (transverse sensitivity at an unknown angle, a mounting turn about an unknown axis), a systematic error
the impacts do not average. Its variance goes into the tilt shapes' angles of the per-roller inverse."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from labctl.physics import RigConfig


def _cross_axis_std(rig: RigConfig, names: Sequence[str]) -> dict[str, tuple[float, tuple[str, str]]]:
    """Per channel: the 1-σ of its coupling to each of its sensor's two other axes, and their channel names.

    A transverse sensitivity T (the sensor class's data-sheet maximum, at an unknown angle) and a mounting turn
    θ (about an unknown axis) each give a perpendicular axis a coefficient of RMS T/√2 and sin θ/√2."""
    u = rig.uncertainty
    out: dict[str, tuple[float, tuple[str, str]]] = {}
    for s in rig.sensors:
        t = u.transverse_sensitivity if s.transverse_sensitivity is None else s.transverse_sensitivity
        theta = u.mounting_angle_rad if s.mounting_angle_rad is None else s.mounting_angle_rad
        sigma = math.hypot(t, math.sin(theta)) / math.sqrt(2.0)
        chans = s.channels
        for i, ch in enumerate(chans):
            if ch in names:
                out[ch] = (sigma, (chans[(i + 1) % 3], chans[(i + 2) % 3]))
    return out


def cross_axis_variance(rig: RigConfig, names: Sequence[str], constants: np.ndarray) -> np.ndarray:
    """(m, n_ch) variance each channel's modal constant gets from its sensor's cross-axis coupling: the other
    axes' constants of the same mode times the coupling's σ (systematic: the impacts do not average it)."""
    info = _cross_axis_std(rig, names)
    index = {c: i for i, c in enumerate(names)}
    out = np.zeros_like(constants, dtype=float)
    for c, (sigma, others) in info.items():
        j = index[c]
        for o in others:
            if o in index:
                out[:, j] += (sigma * constants[:, index[o]]) ** 2
    return out
