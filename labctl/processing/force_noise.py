"""The force channel's noise in a fit's uncertainties (errors in both channels)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from labctl.processing.frf import FrfEstimate, Spectra
from labctl.processing.modes import ForceNoise, Linearised, ModalFit
from labctl.processing.search import channel_weights


class ForceNoiseWidener:
    """Adds the force channel's noise to a fit's uncertainties (errors in both channels): used by the tilt
    pair's resolution test and on the final fit. One per FRF (impacts used, live channels)."""

    def __init__(self, frf: FrfEstimate, spectra: Spectra, used: list[int], sigma_f: np.ndarray, live: np.ndarray,
                 noise: np.ndarray) -> None:
        self.frf, self.spectra, self.used, self.sigma_f, self.live = frf, spectra, used, sigma_f, live
        self.weights = channel_weights(noise[live])
        self.active = bool(spectra.force_windows) and bool(np.any(sigma_f[used] > 0))
        self._noise: dict[tuple[int, int, int], ForceNoise] = {}
        self._done: dict[tuple[int, ...], tuple[ModalFit, ModalFit, Linearised]] = {}

    def force_noise(self, band: slice) -> ForceNoise:
        key = (band.start, band.stop, band.step)
        fn = self._noise.get(key)
        if fn is None:
            fn = self._noise[key] = force_noise_on(self.spectra, self.used, self.sigma_f, band)
        return fn

    def linearised(self, fit: ModalFit, band: slice) -> Linearised | None:
        """The linearised fit made when ``fit`` was widened (None if it was not)."""
        hit = self._done.get((id(fit), band.start, band.stop, band.step))
        return hit[2] if hit is not None and hit[0] is fit else None

    def __call__(self, fit: ModalFit, band: slice) -> ModalFit:
        if not self.active:
            return fit
        key = (id(fit), band.start, band.stop, band.step)
        hit = self._done.get(key)
        if hit is not None and hit[0] is fit:
            return hit[1]
        try:
            lin = Linearised(fit, self.frf.frequencies_hz[band], self.frf.h1[self.live][:, band].astype(complex),
                             self.spectra.decay_rate_per_s, self.weights)
        except np.linalg.LinAlgError:
            return replace(fit, frequency_std_hz=np.full_like(fit.frequency_std_hz, np.inf))
        fn = self.force_noise(band)
        cov = lin.force_covariance(fn, range(len(fn.windows)))
        var = np.clip(np.diag(cov), 0.0, None)
        f_std = np.sqrt(fit.frequency_std_hz**2 + var[0::2])
        z_std = np.sqrt(fit.damping_std**2 + (fit.damping_ratios**2) * var[1::2])
        out = replace(fit, frequency_std_hz=f_std, damping_std=z_std, force_covariance=cov)
        self._done[key] = (fit, out, lin)
        self._done[(id(out), band.start, band.stop, band.step)] = (out, out, lin)
        return out


def force_noise_on(spectra: Spectra, used: list[int], sigma_f: np.ndarray, band: slice) -> ForceNoise:
    lines = np.arange(spectra.frequencies_hz.shape[0])[band]
    return ForceNoise(spectra=spectra.force[:, band][used].astype(complex), line_index=lines,
                      n_fft=spectra.n_samples, windows=tuple(spectra.force_windows[i] for i in used),
                      sigma_n=sigma_f[used])
