"""The step's FRF so far, for the per-hit gate: the blows of the step being acquired, averaged with the
project's one estimator (``labctl.processing.frf``) before the step is identified.

``StepBlows`` is an engine subscriber: it runs in the engine thread, so a blow is kept before the engine
asks for its verdict, and the gate (UI thread) finds it there. The verdicts of earlier blows come from the
caller (the operator's answers), the checks' verdict standing where there is none.
"""

from __future__ import annotations

import threading
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from drivers.interfaces import ImpactReview
from labctl import events as ev
from labctl.errors import LabctlError
from labctl.processing.frf import blow_spectra, estimate_frf
from labctl.tui.plotdata import FRF_SPAN_HZ, vertical_channels


@dataclass(frozen=True)
class StepFrf:
    """|H1| and coherence (n_ch, n_f) of a step's blows ``attempts`` (the one under review last)."""

    step: int
    attempts: tuple[int, ...]
    frequencies_hz: np.ndarray
    h1_magnitude: np.ndarray
    coherence: np.ndarray
    channels: tuple[str, ...]
    band_coherence: float  # mean over the vertical channels, 0–FRF_SPAN_HZ
    band_coherence_before: float | None  # the same without the blow under review (None: fewer than two other
    # blows, whose coherence would be 1 by definition)

    def title(self) -> str:
        """One line for the gate: how many blows are averaged and what this one does to the coherence."""
        n = len(self.attempts)
        text = f"FRF of step {self.step} so far: {n} blow{'s' if n != 1 else ''} averaged, this one included"
        if self.band_coherence_before is not None:
            text += (f" · coherence 0–{FRF_SPAN_HZ / 1e3:g} kHz {self.band_coherence_before:.3f} → "
                     f"{self.band_coherence:.3f} with it")
        return text


def band_coherence(frequencies_hz: np.ndarray, coherence: np.ndarray, channels: tuple[str, ...]) -> float:
    """Mean coherence of the vertical channels over the FRF span shown."""
    band = (frequencies_hz > 0) & (frequencies_hz <= FRF_SPAN_HZ)
    return float(np.mean(coherence[vertical_channels(channels)][:, band]))


@dataclass(frozen=True)
class _Blow:
    attempt: int
    accepted: bool  # the checks' verdict
    sample_rate_hz: float
    force_n: np.ndarray
    accel_m_per_s2: np.ndarray
    channels: tuple[str, ...]


class StepBlows:
    """Keeps the blows of the step being acquired (this session's; a resumed step's earlier blows are in the file)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._step: tuple[int, int, int] | None = None
        self._blows: dict[int, _Blow] = {}

    def __call__(self, event: ev.Event) -> None:
        if not isinstance(event, ev.StepStarted | ev.ImpactAcquired):
            return
        p = event.position
        with self._lock:
            if (p.series, p.run, p.step) != self._step:
                self._step, self._blows = (p.series, p.run, p.step), {}
            if isinstance(event, ev.ImpactAcquired):
                self._blows[event.attempt] = _Blow(event.attempt, event.accepted, event.sample_rate_hz,
                                                   event.force_n, event.accel_m_per_s2, event.channels)

    def frf_so_far(self, review: ImpactReview, verdicts: Mapping[int, bool]) -> StepFrf | None:
        """H1 over the step's accepted blows and the one under review (``verdicts``: the operator's by attempt).

        None when the blow is not at hand or the blows cannot be averaged (different records, no pulse).
        """
        with self._lock:
            if self._step != (review.series, review.run, review.step) or review.attempt not in self._blows:
                return None
            earlier = [b for a, b in sorted(self._blows.items())
                       if a != review.attempt and verdicts.get(a, b.accepted)]
            blows = [*earlier, self._blows[review.attempt]]
        try:
            spectra = blow_spectra(np.stack([b.force_n for b in blows]), np.stack([b.accel_m_per_s2 for b in blows]),
                                   blows[-1].sample_rate_hz)
            frf = estimate_frf(spectra, range(len(blows)))
            before = estimate_frf(spectra, range(len(earlier))) if len(earlier) >= 2 else None
        except (LabctlError, ValueError):
            return None
        channels = blows[-1].channels
        return StepFrf(review.step, tuple(b.attempt for b in blows), frf.frequencies_hz, np.abs(frf.h1),
                       frf.coherence, channels, band_coherence(frf.frequencies_hz, frf.coherence, channels),
                       None if before is None else band_coherence(before.frequencies_hz, before.coherence, channels))
