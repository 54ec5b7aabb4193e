"""Rig calibration fit: the model frequencies of every ball step in one batched eigen-analysis against one
``rig_modes`` call per step (the previous ``predict_hz``), on the same observations, in one run.

Prints the CPU time per ``predict_hz`` call both ways, their ratio, the largest relative difference of the
frequencies, and the CPU time of a whole ``fit_rig`` with the batched model.

    python bench/calibration_fit.py [--repeat 200]

Run by hand (not a test).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from labctl.calibration import BallStep, fit_rig  # noqa: E402
from labctl.calibration.fit import Observations, predict_hz  # noqa: E402
from labctl.physics import HertzBallContact, load_rig, material, rig_modes  # noqa: E402

LOADS = (38.0, 77.0, 116.0, 155.0, 194.0, 233.0, 272.0, 311.0, 350.0, 389.0, 428.0)


def per_step_predict_hz(rig, obs: Observations) -> np.ndarray:  # noqa: ANN001
    """The previous implementation: one scipy generalised eigenproblem per step."""
    out = np.empty(obs.hz.size)
    cache: dict[int, tuple[float, float]] = {}
    for j, (i, tilt) in enumerate(zip(obs.step_of, obs.is_tilt, strict=True)):
        if i not in cache:
            modes = rig_modes(rig, obs.stiffness_n_per_m[i])
            cache[i] = (modes.bounce_hz, float(np.mean(modes.tilt_hz)))
        out[j] = cache[i][1] if tilt else cache[i][0]
    return out


def ball_steps(rig) -> list[BallStep]:  # noqa: ANN001
    """Two seatings each of 6 and 9 mm balls at the protocol's loads, frequencies from the rig model read with
    their stated noise (0.2 mHz bounce, 2 mHz tilt; seed 1)."""
    steel = material("1.3505")
    rng = np.random.default_rng(1)
    steps = []
    for diameter_mm in (6.0, 9.0):
        contact = HertzBallContact(diameter_mm * 1e-3, steel, steel)
        for run in (1, 2):
            for f in LOADS:
                modes = rig_modes(rig, float(contact.stiffness_n_per_m(f)))
                steps.append(BallStep(f"{diameter_mm} mm run {run} {f} N", f"{diameter_mm}:{run}", f, f, contact,
                                      modes.bounce_hz + 2e-4 * rng.standard_normal(), 2e-4,
                                      float(np.mean(modes.tilt_hz)) + 2e-3 * rng.standard_normal(), 2e-3))
    return steps


def cpu_per_call(fn, repeat: int) -> float:  # noqa: ANN001
    t = time.process_time()
    for _ in range(repeat):
        fn()
    return (time.process_time() - t) / repeat


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=200)
    args = ap.parse_args()
    rig = load_rig()
    steps = ball_steps(rig)
    obs = Observations.of(steps)
    old = cpu_per_call(lambda: per_step_predict_hz(rig, obs), args.repeat)
    new = cpu_per_call(lambda: predict_hz(rig, obs), args.repeat)
    diff = float(np.max(np.abs(predict_hz(rig, obs) / per_step_predict_hz(rig, obs) - 1)))
    t = time.process_time()
    fit_rig(rig, steps)
    fit_cpu = time.process_time() - t
    print(f"predict_hz over {len(steps)} ball steps ({obs.hz.size} frequencies), CPU per call: "
          f"per-step rig_modes {old * 1e3:.2f} ms, batched {new * 1e3:.2f} ms, ratio {old / new:.1f}x; "
          f"largest relative difference {diff:.1e}")
    print(f"fit_rig with the batched model: {fit_cpu:.2f} s CPU")
    return 0


if __name__ == "__main__":
    sys.exit(main())
