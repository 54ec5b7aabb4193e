"""Does ``labctl compare`` hold its stated level, and what can it detect? Prints, per design, the share of
null comparisons called significant (should be ≤ the level) and the share of real differences found.

Two sources of curves:
- synthetic (default): repetition curves with a structure the test does not assume — a seating offset shared by
  all loads of a curve, load-dependent noise, Student-t (4 dof) tails, unequal scatter between the groups, step
  loads jittered from curve to curve, and (``campaign`` designs) a day-to-day offset per campaign;
- ``--twin N``: N pairs of campaigns of the shipped protocol on the simulated rig with different seeds (null:
  same rails; and one Ra 0.03 µm campaign against each Ra 0.2 µm one).

    python bench/compare_level.py [--trials 2000] [--twin 0] [--level 0.05]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from intervals import wilson  # noqa: E402

from labctl.compare import Curve, compare_groups, load_group  # noqa: E402

LOADS_N = np.linspace(38.0, 440.0, 11)


def _baseline(f: np.ndarray) -> np.ndarray:
    return 6.6e8 * (np.log(f / 6.0) / np.log(440.0 / 6.0)) ** 0.9  # a roughness-like curve, not the test's form


def _curve(rng: np.random.Generator, campaign: str, shift: float, scatter: float, effect: float) -> Curve:
    f = LOADS_N + rng.normal(0.0, 0.8, LOADS_N.size)
    seat = rng.normal(0.0, 0.006 * scatter)
    point = scatter * (0.002 + 0.02 * (38.0 / f) ** 1.5) * rng.standard_t(4, f.size) / np.sqrt(2.0)
    k = _baseline(f) * np.exp(seat + shift + point) * (1.0 + effect * (38.0 / f) ** 0.5)
    return Curve("synthetic", campaign, f, k)


def _group(rng: np.random.Generator, campaigns: int, reps: int, scatter: float, effect: float,
           day_sigma: float) -> list[Curve]:
    out = []
    for c in range(campaigns):
        shift = rng.normal(0.0, day_sigma)
        out += [_curve(rng, f"c{c}", shift, scatter, effect) for _ in range(reps)]
    return out


DESIGNS = {  # name: (campaigns, repetitions per group, unit, day-to-day σ)
    "1 campaign × 3 reps": (1, 3, "repetition", 0.0),
    "2 campaigns × 3 reps": (2, 3, "repetition", 0.0),
    "3 campaigns × 3 reps, day offsets 0.5 %, unit campaign": (3, 3, "campaign", 0.005),
    "3 campaigns × 3 reps, day offsets 0.5 %, unit repetition": (3, 3, "repetition", 0.005),
}


def synthetic(trials: int, level: float) -> None:
    rng = np.random.default_rng(7)
    print(f"synthetic curves, {trials} trials per cell, level {level}: share called significant [95 % interval]")
    print(f"{'design':58s} {'null':>20s} {'+2 % at 38 N':>20s} {'+5 % at 38 N':>20s}")
    for name, (campaigns, reps, unit, day) in DESIGNS.items():
        cells = []
        for effect in (0.0, 0.02, 0.05):
            hits = 0
            for _ in range(trials):
                a = _group(rng, campaigns, reps, 1.0, 0.0, day)
                b = _group(rng, campaigns, reps, 1.5, effect, day)
                hits += compare_groups(a, b, level=level, unit=unit).significant
            p, lo, hi = wilson(hits, trials)
            cells.append(f"{p:.3f} [{lo:.3f}, {hi:.3f}]")
        print(f"{name:58s} " + " ".join(f"{c:>20s}" for c in cells))


def twin(pairs: int, level: float) -> None:
    from labctl.campaign import run_campaign

    smooth = (ROOT / "protocols" / "roller_stiffness.toml").read_text(encoding="utf-8").replace(
        "rail_ra_um = 0.2", "rail_ra_um = 0.03")
    null_hits = ra_hits = 0
    with tempfile.TemporaryDirectory() as tmp:
        proto = Path(tmp) / "smooth.toml"
        proto.write_text(smooth, encoding="utf-8")
        for i in range(pairs):
            files = []
            for j, protocol in enumerate(("roller_stiffness", "roller_stiffness", str(proto))):
                out = Path(tmp) / f"p{i}_{j}.h5"
                run_campaign(protocol, out=str(out), backend="sim", seed=1000 + 3 * i + j)
                files.append(load_group(str(out)))
            null_hits += compare_groups(files[0], files[1], level=level).significant
            ra_hits += compare_groups(files[0], files[2], level=level).significant
            for f in Path(tmp).glob("p*.h5"):
                f.unlink()
    for name, hits in (("twin, same rails, other seed (null)", null_hits), ("twin, Ra 0.2 vs Ra 0.03", ra_hits)):
        p, lo, hi = wilson(hits, pairs)
        print(f"{name:58s} {hits}/{pairs} significant = {p:.2f} [{lo:.2f}, {hi:.2f}]")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=2000)
    ap.add_argument("--twin", type=int, default=0, help="pairs of twin campaigns (about 1 min of CPU per pair)")
    ap.add_argument("--level", type=float, default=0.05)
    args = ap.parse_args()
    synthetic(args.trials, args.level)
    if args.twin:
        twin(args.twin, args.level)


if __name__ == "__main__":
    main()
