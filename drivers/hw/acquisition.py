"""What the real DAQ backends share: the wiring of their inputs, a software force trigger on a sample stream,
and the assembly of a :class:`Record` in physical units."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from drivers.interfaces import Channel, Record, TriggerSpec


@dataclass(frozen=True)
class InputWiring:
    """One DAQ input as wired on the rig: the interface's Channel and the terminal it is plugged into.

    ``terminal`` is the MCC analog input number (``"0"``…``"7"``) or an NI physical channel
    (``"cDAQ1Mod1/ai0"``); ``adc_range_v`` the input range to use, ``None`` for the smallest that holds the
    sensor's full scale.
    """

    channel: Channel
    terminal: str
    adc_range_v: float | None = None

    @property
    def full_scale_v(self) -> float:
        return self.channel.range_units * self.channel.sensitivity_v_per_unit


def check_wiring(device: str, wiring: Sequence[InputWiring]) -> tuple[int, tuple[int, ...]]:
    """Index of the single force input and of the acceleration inputs; ValueError naming the problem."""
    names = [w.channel.name for w in wiring]
    if len(set(names)) != len(names):
        raise ValueError(f"{device}: channel names repeat: {names}")
    terminals = [w.terminal for w in wiring]
    if len(set(terminals)) != len(terminals):
        raise ValueError(f"{device}: two channels on one input: {terminals}")
    force = [i for i, w in enumerate(wiring) if w.channel.kind == "force"]
    if len(force) != 1:
        raise ValueError(f"{device}: expected exactly one force channel, got {len(force)}")
    accel = tuple(i for i, w in enumerate(wiring) if w.channel.kind == "acceleration")
    if not accel:
        raise ValueError(f"{device}: expected at least one acceleration channel")
    for w in wiring:
        if not (w.channel.sensitivity_v_per_unit > 0 and w.channel.range_units > 0):
            raise ValueError(f"{device}: channel {w.channel.name}: sensitivity and range must be positive")
    return force[0], accel


def samples_at_rate(n_samples: int, requested_hz: float, actual_hz: float) -> int:
    """The sample count that keeps the duration ``n_samples / requested_hz`` at the rate a DAQ really runs at."""
    return max(2, round(n_samples / requested_hz * actual_hz))


def make_record(wiring: Sequence[InputWiring], data: np.ndarray, sample_rate_hz: float, trigger_index: int,
                timestamp_s: float, clipped: Sequence[str] = ()) -> Record:
    """Split physical-unit rows (in ``wiring`` order) into force and accelerations; flag channels at range."""
    force_row, accel_rows = check_wiring("daq", wiring)
    at_range = {w.channel.name for w, row in zip(wiring, data, strict=True)
                if row.size and float(np.max(np.abs(row))) >= w.channel.range_units}
    flagged = at_range | set(clipped)
    return Record(
        sample_rate_hz=float(sample_rate_hz),
        force_n=np.asarray(data[force_row], dtype=float),
        accel_m_per_s2=np.asarray(data[list(accel_rows)], dtype=float),
        channels=tuple(wiring[i].channel.name for i in accel_rows),
        trigger_index=int(trigger_index),
        timestamp_s=float(timestamp_s),
        clipped=tuple(w.channel.name for w in wiring if w.channel.name in flagged),
    )


class StreamTrigger:
    """Rising force-level trigger on streamed blocks, keeping ``pretrigger_samples`` before the crossing.

    A crossing counts only once ``pretrigger_samples`` have streamed and the force has been below the level
    (a force already above it when the stream starts is not an impact).
    """

    def __init__(self, n_channels: int, n_samples: int, force_row: int, trigger: TriggerSpec) -> None:
        if not 0 <= trigger.pretrigger_samples < n_samples:
            raise ValueError(f"pretrigger_samples = {trigger.pretrigger_samples}: expected 0 to {n_samples - 1}")
        self.n_samples, self.force_row = n_samples, force_row
        self.level, self.pre = trigger.level_n, trigger.pretrigger_samples
        self._history = np.zeros((n_channels, 0))
        self._seen = 0
        self._prev_below = False  # the first sample of the stream can never be a crossing
        self._record: np.ndarray | None = None
        self._filled = 0
        self.trigger_sample: int | None = None  # stream index of the crossing

    @property
    def done(self) -> bool:
        return self._record is not None and self._filled >= self.n_samples

    def feed(self, block: np.ndarray) -> bool:
        """Consume one (n_channels, m) block; True once the record is complete."""
        if self._record is not None:
            self._append(block)
            return self.done
        start = self._seen
        self._seen += block.shape[1]
        force = block[self.force_row]
        hit = self._first_crossing(force, force < self.level, start)
        if hit is None:
            self._history = np.concatenate([self._history, block], axis=1)[:, -self.pre:] if self.pre else block[:, :0]
            return False
        self.trigger_sample = start + hit
        joined = np.concatenate([self._history, block], axis=1)
        first = self._history.shape[1] + hit - self.pre
        self._record = np.empty((block.shape[0], self.n_samples))
        self._filled = 0
        self._append(joined[:, first:])
        return self.done

    def record(self) -> np.ndarray:
        if not self.done:
            raise RuntimeError("record not complete")
        assert self._record is not None
        return self._record

    def _first_crossing(self, force: np.ndarray, below: np.ndarray, start: int) -> int | None:
        previous = np.r_[self._prev_below, below[:-1]]
        eligible = np.arange(start, start + force.size) >= self.pre  # hold off until the pretrigger is full
        self._prev_below = bool(below[-1]) if below.size else self._prev_below
        hits = np.flatnonzero(~below & previous & eligible)
        return int(hits[0]) if hits.size else None

    def _append(self, block: np.ndarray) -> None:
        assert self._record is not None
        take = min(self.n_samples - self._filled, block.shape[1])
        self._record[:, self._filled:self._filled + take] = block[:, :take]
        self._filled += take
