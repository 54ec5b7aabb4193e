"""Which response channels a step can use: live ones, their noise floors, and those saturated in every impact."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from labctl.processing.checks import LOW_COHERENCE, OVERLOAD, ImpactCheck
from labctl.processing.errors import ProcessingError
from labctl.processing.frf import FrfEstimate


def channel_noise(accel: np.ndarray, used: list[int]) -> np.ndarray:
    """Each channel's noise floor: its spread over the record's last part, where the response has died out."""
    tail = accel[used, :, -min(accel.shape[-1] // 4, 2048):]
    return np.sqrt(np.mean(np.var(tail, axis=-1), axis=0))


def live_channels(frf: FrfEstimate) -> np.ndarray:
    """Channels with signal: a flat (dead) sensor leaves a response spectrum of round-off only."""
    power = frf.response_power
    live = power > 1e-12 * float(power.max(initial=0.0))
    if not live.any():
        raise ProcessingError("every response channel is flat: no sensor signal")
    return live


def saturated_channels(checks: Sequence[ImpactCheck], names: Sequence[str]) -> tuple[str, ...]:
    """Response channels overloaded in every impact: they carry no usable impact, the others still do."""
    if not checks:
        return ()
    every = set(names)
    for c in checks:
        every &= set(c.overloaded)
    return tuple(n for n in names if n in every)


def rail_touches(checks: Sequence[ImpactCheck], accel: np.ndarray, names: Sequence[str]) -> list[ImpactCheck]:
    """The checks with a channel's overload added to each impact whose extreme reaches, even for one sample, a
    level at which that channel clipped (a repeated extreme) in another impact: the same rail, touched briefly,
    is a clip that one impact alone cannot show."""
    out = list(checks)
    for c, name in enumerate(names):
        clipped = [i for i, check in enumerate(checks) if name in check.overloaded]
        if not clipped or len(clipped) == len(checks):
            continue
        for extreme in (np.max, np.min):
            levels = [(float(extreme(accel[i, c])), accel[i, c]) for i in clipped]
            rails = {v for v, x in levels if np.count_nonzero(x == v) > 1}
            for i, check in enumerate(out):
                if rails and name not in check.overloaded and float(extreme(accel[i, c])) in rails:
                    note = f"near full scale: {name} reaches the level it clipped at in impact {clipped[0]}"
                    out[i] = replace(check.rejected_for(OVERLOAD, note), overloaded=(*check.overloaded, name))
    return out


def without_overload_of(check: ImpactCheck, dropped: tuple[str, ...]) -> ImpactCheck:
    """The check with the dropped channels' overload forgiven (the impact may still fail for other reasons)."""
    rest = tuple(n for n in check.overloaded if n not in dropped)
    if rest or LOW_COHERENCE in check.reasons or "overload" not in check.reasons:
        return check
    reasons = tuple(r for r in check.reasons if r != "overload")
    notes = tuple(n for n in check.notes if not n.startswith("near full scale"))
    notes = (*notes, f"saturated channel(s) {', '.join(dropped)} dropped from the step")
    return replace(check, accepted=not reasons, reasons=reasons, notes=notes)
