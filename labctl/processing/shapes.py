"""Bounce or tilt? Identified mode shapes against the rig model's predicted shapes over the live sensors.

Bounce: the top sensors move in phase and the bottom one opposite. Tilt: the top sensors sum to about zero
and the bottom centre stays still. The rig model (labctl.physics.rig_modes, equal rollers) gives both
shapes at every channel from the sensor positions in the rig file; only the channels that carry signal are
compared, so a dead sensor just removes its rows. Each identified mode gets the MAC with the bounce shape
and the fraction of its shape inside the two-dimensional tilt subspace; the most bounce-like mode is the
bounce. When the live channels cannot tell the two apart (e.g. one channel), the predicted frequency
order decides.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from labctl.physics import RigConfig, bounce_hz, rig_modes
from labctl.processing.rig_memo import RigMemo

NOMINAL_STIFFNESS_N_PER_M = 5.0e7  # sensor-level shapes of equal rollers barely depend on k
RIGID_ROLLERS_N_PER_M = 1.0e13
MIN_SEPARATION = 0.2  # below this the live channels cannot tell bounce from tilt


@dataclass(frozen=True)
class PredictedShapes:
    """The rig model's contact-mode shapes over the data's channels, with the predicted order."""

    channels: tuple[str, ...]
    bounce: np.ndarray  # (n_ch,)
    tilt: np.ndarray  # (2, n_ch)
    bounce_hz: float
    tilt_hz: float
    support_hz: float
    max_bounce_hz: float  # what the setup stiffness alone allows: no contact mode lies above


@dataclass(frozen=True)
class Classification:
    """Which fitted mode is the bounce, which are tilt, and how clearly the shapes said so."""

    bounce: int
    tilt: tuple[int, ...]
    bounce_mac: np.ndarray  # per fitted mode
    tilt_fraction: np.ndarray  # per fitted mode
    by_shape: bool  # False: the live channels could not separate the shapes; frequency order was used


def predicted_shapes(rig: RigConfig, channels: Sequence[str]) -> PredictedShapes:
    """Bounce and tilt shapes of the rig model at the given channels (built once per rig object)."""
    return _SHAPES(rig, channels)


def _predicted_shapes(rig: RigConfig, channels: Sequence[str]) -> PredictedShapes:
    modes = rig_modes(rig, NOMINAL_STIFFNESS_N_PER_M)

    def at(mode: int) -> np.ndarray:
        shape = modes.sensor_shapes(mode)
        return np.array([shape[c] for c in channels])

    return PredictedShapes(
        channels=tuple(channels),
        bounce=at(modes.bounce),
        tilt=np.stack([at(modes.tilt[0]), at(modes.tilt[1])]),
        bounce_hz=modes.bounce_hz,
        tilt_hz=float(np.mean(modes.tilt_hz)),
        support_hz=float(max(modes.frequencies_hz[i] for i in modes.support)),
        max_bounce_hz=bounce_hz(rig, RIGID_ROLLERS_N_PER_M),
    )


_SHAPES = RigMemo(_predicted_shapes)


def _tilt_projector(tilt: np.ndarray) -> np.ndarray:
    u, sv, _ = np.linalg.svd(tilt.T, full_matrices=False)
    keep = sv > 1e-9 * max(float(sv.max(initial=0.0)), 1e-300)
    basis = u[:, keep]
    return basis @ basis.T


def separation(pred: PredictedShapes, live: np.ndarray) -> float:
    """1 - the share of the bounce shape inside the tilt subspace, over the live channels (1 = fully distinct)."""
    b = pred.bounce[live]
    nb = float(b @ b)
    if nb <= 0:
        return 0.0
    p = _tilt_projector(pred.tilt[:, live])
    return 1.0 - float(b @ p @ b) / nb


def classify(constants: np.ndarray, frequencies_hz: np.ndarray, pred: PredictedShapes,
             live: np.ndarray) -> Classification:
    """Assign the fitted modes (constants: (M, n_ch)) to bounce and tilt."""
    phi = constants[:, live]
    b = pred.bounce[live]
    p = _tilt_projector(pred.tilt[:, live])
    norms = np.maximum(np.sum(phi**2, axis=1), 1e-300)
    mac = (phi @ b) ** 2 / (norms * max(float(b @ b), 1e-300))
    tilt_frac = np.einsum("rc,cd,rd->r", phi, p, phi) / norms
    by_shape = separation(pred, live) >= MIN_SEPARATION
    if by_shape:
        bounce = int(np.argmax(mac - tilt_frac))
    else:
        order = np.argsort(frequencies_hz)
        bounce = int(order[-1] if pred.bounce_hz >= pred.tilt_hz else order[0])
    tilt = tuple(int(i) for i in np.argsort(frequencies_hz) if i != bounce)
    return Classification(bounce, tilt, mac, tilt_frac, by_shape)


def signed_shape(values: np.ndarray) -> np.ndarray:
    """A mode shape scaled to a largest component of +1."""
    if not values.size:
        return values
    k = int(np.argmax(np.abs(values)))
    return values / values[k] if values[k] != 0 else values
