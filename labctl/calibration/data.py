"""Ball-verification steps read from campaign files: what the calibration fits (the one place that reads storage)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from labctl.errors import InputError
from labctl.physics.hertz import HertzBallContact
from labctl.physics.materials import material
from labctl.storage import CampaignReader


@dataclass(frozen=True)
class BallStep:
    """One identified load step with balls between the rails: measured modes, load and the ball contact."""

    source: str  # file:series/run/step
    run_key: str  # one seating of the balls (file, series, repetition): steps sharing it share their scatter
    load_n: float  # load per ball
    load_repeat_n: float | None  # a second load-cell reading of the same step (its difference is load noise)
    contact: HertzBallContact
    bounce_hz: float
    bounce_std_hz: float
    tilt_hz: float | None  # mean of the tilt pair (None: not identified)
    tilt_std_hz: float | None

    @property
    def ball_diameter_m(self) -> float:
        return self.contact.diameter_m


@dataclass(frozen=True)
class CampaignBalls:
    """Ball steps of one campaign file, its stored rig text and the series it could not use (with why)."""

    path: str
    steps: list[BallStep]
    rig_text: str | None
    skipped: list[str]


def _finite(value: object) -> float | None:
    try:
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def read_ball_steps(path: str | Path) -> CampaignBalls:
    """Every identified ball step of a campaign file (steps without a stored result are skipped, not guessed)."""
    steps: list[BallStep] = []
    skipped: list[str] = []
    with CampaignReader(path) as reader:
        rig_text = reader.config_text("rig.toml")
        for series in reader.series_indices():
            spec = reader.specimen(series)
            label = spec.label or f"series {series}"
            if spec.kind != "ball":
                skipped.append(f"{path}: series {series} ({label}) is not a ball specimen")
                continue
            diameter = _finite(spec.ball_diameter_m)
            if diameter is None or diameter <= 0:
                raise InputError(f"{path}: series {series}: ball_diameter_m = {spec.ball_diameter_m!r}: "
                                 "expected a positive diameter in m")
            contact = HertzBallContact(diameter, material(spec.material or "1.3505"),
                                       material(spec.rail_material or "1.3505"))
            for run in reader.runs(series):
                for step in run.steps:
                    r = step.result
                    where = f"{path}:series {series}/run {run.run}/step {step.step}"
                    bounce = _finite(r.bounce_hz) if r is not None and r.identified else None
                    load = _finite(step.load_n)
                    if r is None or bounce is None or load is None or load <= 0:
                        skipped.append(f"{where}: no identified bounce frequency or load")
                        continue
                    t = [_finite(v) for v in r.tilt_hz]
                    ts = [_finite(v) for v in r.tilt_hz_std]
                    tilt_ok = len(t) == 2 and all(v is not None and v > 0 for v in t) and len(ts) == 2 \
                        and all(v is not None for v in ts)
                    tilt_hz = tilt_std_hz = None
                    if tilt_ok:
                        tilt_hz = 0.5 * (t[0] + t[1])  # type: ignore[operator]
                        # an unresolved pair is one peak between the two: its half-split is unknown, so widen
                        tilt_std_hz = 0.5 * math.hypot(ts[0], ts[1])  # type: ignore[arg-type]
                        if not r.tilt_pair_resolved:
                            tilt_std_hz = max(tilt_std_hz, 0.002 * tilt_hz)
                    steps.append(BallStep(
                        source=where, run_key=f"{path}:{series}:{run.run}", load_n=load,
                        load_repeat_n=_finite(step.load_after_n), contact=contact,
                        bounce_hz=bounce, bounce_std_hz=float(_finite(r.bounce_hz_std) or 0.0),
                        tilt_hz=tilt_hz, tilt_std_hz=tilt_std_hz))
    return CampaignBalls(str(path), steps, rig_text, skipped)
