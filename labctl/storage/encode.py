"""How the writer encodes values: attributes (nested values as JSON) and traces (exact ADC counts with a
per-channel scale when the samples are whole converter steps, else float32 with shuffle + gzip)."""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import asdict, is_dataclass
from typing import Any

import h5py
import numpy as np

from labctl.storage import schema as s
from labctl.storage.records import ImpactRecord

__all__ = ["ADC_BITS", "COHERENCE_DECIMALS", "COMPRESS", "_attrs", "_write_trace", "adc_counts", "impact_attrs",
           "write_frf"]


def _attrs(obj: h5py.Group | h5py.Dataset, values: Mapping[str, Any]) -> None:
    for key, value in values.items():
        if value is not None:
            obj.attrs[key] = _attr_value(value)


def _dumps(value: Any) -> Any:
    """JSON for nested values (dataclasses included)."""
    return json.dumps(value, default=lambda o: asdict(o) if is_dataclass(o) else str(o))


def _attr_value(value: Any) -> Any:
    if is_dataclass(value) and not isinstance(value, type):
        return _dumps(value)
    if isinstance(value, list | tuple | dict) and not (isinstance(value, list | tuple) and value
                                                         and all(isinstance(v, int | float) for v in value)):
        return _dumps(value)
    return value


ADC_BITS = (24, 16, 18, 20, 22, 12, 14)  # common converter resolutions, most likely first
COMPRESS = {"compression": "gzip", "compression_opts": 4, "shuffle": True}
COHERENCE_DECIMALS = 4  # the stored coherence (derived, recomputable from the raw impacts) is kept to 1e-4


def adc_counts(x: np.ndarray, range_units: float | None) -> tuple[np.ndarray, float] | None:
    """``x`` as integer counts of an ADC spanning ±``range_units`` and the step per count, if that is exact.

    Exact means counts × step reproduces every sample bit for bit, so storing counts loses nothing.
    """
    if range_units is None or not np.isfinite(range_units) or range_units <= 0 or not np.isfinite(x).all():
        return None
    probe = x[:256]
    for bits in ADC_BITS:
        step = 2.0 * float(range_units) / 2.0**bits
        if not np.array_equal(np.rint(probe / step) * step, probe):  # cheap refusal on the first samples
            continue
        k = np.rint(x / step)
        if np.abs(k).max(initial=0.0) <= 2.0**31 - 1 and np.array_equal(k * step, x):
            return k.astype(np.int32), step
    return None


def _write_trace(g: h5py.Group, name: str, x: np.ndarray, ranges: Sequence[float | None]
                 ) -> tuple[h5py.Dataset, np.ndarray]:
    """A trace as integer counts with per-channel ``scale`` (scale-offset filter) when the samples are exact
    ADC steps, else as float32 with shuffle + gzip; with the values a reader will get back (no read needed)."""
    x = np.asarray(x, dtype=float)
    rows = x.reshape(-1, x.shape[-1])
    coded = [adc_counts(row, r) for row, r in zip(rows, ranges, strict=True)] if len(ranges) == len(rows) else [None]
    n = x.shape[-1]
    chunks = (1, min(n, s.TRACE_CHUNK)) if x.ndim == 2 else (min(n, s.TRACE_CHUNK),)
    if all(c is not None for c in coded):
        counts = np.stack([c[0] for c in coded]).reshape(x.shape)  # type: ignore[index]
        scale = [c[1] for c in coded]  # type: ignore[index]
        ds = g.create_dataset(name, data=counts, chunks=chunks, scaleoffset=0)
        ds.attrs["scale"] = scale if x.ndim == 2 else scale[0]
        ds.attrs["offset"] = [0.0] * len(scale) if x.ndim == 2 else 0.0
        return ds, x  # counts × scale reproduce every sample (adc_counts checked it)
    stored = x.astype(np.float32)
    return g.create_dataset(name, data=stored, chunks=chunks, **COMPRESS), stored.astype(float)


def impact_attrs(record: ImpactRecord) -> dict[str, Any]:
    """An impact group's attributes: its acquisition facts, the checks' findings and the verdict."""
    info = record.info
    return {"attempt": record.attempt, "sample_rate_hz": info.sample_rate_hz,
            "trigger_index": info.trigger_index, "timestamp_utc": info.timestamp_utc,
            "clipped": list(info.clipped), "check_accepted": bool(info.checks.accepted),
            "peak_force_n": info.checks.peak_force_n, "pulse_width_s": info.checks.pulse_width_s,
            "accepted": bool(info.verdict.accepted), "verdict_source": info.verdict.source,
            "verdict_reason": info.verdict.reason, "reasons": list(info.reasons)}


def write_frf(g: h5py.Group, frf: Any) -> None:
    """A step's FRF up to ``FRF_MAX_HZ`` at about ``FRF_SPACING_HZ`` (H1 as complex64, coherence to 1e-4)."""
    f_hz = np.asarray(frf.frequencies_hz)
    stride = max(1, round(s.FRF_SPACING_HZ / (f_hz[1] - f_hz[0]))) if f_hz.size > 1 else 1
    keep = np.flatnonzero(f_hz <= s.FRF_MAX_HZ)[::stride]
    g.create_dataset("frequencies_hz", data=np.asarray(frf.frequencies_hz)[keep], **COMPRESS)
    g.create_dataset("h1", data=np.asarray(frf.h1)[..., keep].astype(np.complex64), **COMPRESS)
    coh = np.asarray(frf.coherence)[..., keep].astype(np.float32)  # 0..1: four decimals are all it carries
    g.create_dataset("coherence", data=coh, scaleoffset=COHERENCE_DECIMALS,
                     chunks=coh.shape if coh.ndim == 1 else (1, coh.shape[-1]))
