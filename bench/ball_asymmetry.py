"""Can ball runs (`labctl calibrate`) pin down the discs' inertia asymmetry? The numbers behind the answer.

Run by hand::

    python bench/ball_asymmetry.py

With equal balls the tilt split would be the rig's own; but balls are equal only to their seating scatter, and
each seating's inequality splits the tilt pair too. For the paper's rig at ball stiffnesses over the range of a
ball campaign this prints: the split per unit inertia asymmetry and per roller deviation, the split (RMS over
random seatings) that a ball stiffness scatter of 0.3 % (the balls world) and 3 % (the paper's bound on its ball
runs) produces, as an equivalent asymmetry, the seatings needed to pin the asymmetry below the rig file's prior,
and the split of that prior against the tilt modes' half-power bandwidth (what a step can resolve).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from labctl.physics import load_rig  # noqa: E402
from labctl.physics.rig import ContactModeModel  # noqa: E402


def main() -> int:
    rig = load_rig()
    prior = rig.uncertainty.inertia_asymmetry_rel
    model = ContactModeModel.of(rig)
    rng = np.random.default_rng(1)
    print(f"# paper rig; inertia asymmetry prior {100 * prior:g} % (rig file); 4000 random seatings per row\n")
    print("| k N/m | tilt Hz | split per 1 % asymmetry Hz | prior's split / half-power width Hz | ball scatter | "
          "RMS split Hz | = asymmetry (per component) | seatings for σ ≤ prior | seatings for σ ≤ ½ prior |")
    print("|---" * 9 + "|")
    for k in (1.0e7, 1.435e7, 3.0e7, 4.7e7):
        f0, _ = model.many(np.full((1, 3), k))
        fa, _ = model.many(np.full((1, 3), k), np.array([[0.01, 0.0]]))
        per_pct = float(fa[0, 2] - fa[0, 1])
        width = 2.0 * rig.modal_damping_ratio * float(f0[0, 1])
        for scatter in (0.003, 0.03):
            f, _ = model.many(k * (1.0 + scatter * rng.standard_normal((4000, 3))))
            rms = float(np.sqrt(np.mean((f[:, 2] - f[:, 1]) ** 2)))
            equiv = rms / per_pct / 100.0 / np.sqrt(2.0)  # one component of the 2-D asymmetry (u, v)
            n1, n2 = int(np.ceil((equiv / prior) ** 2)), int(np.ceil((equiv / (0.5 * prior)) ** 2))
            print(f"| {k:.3g} | {f0[0, 1]:.0f} | {per_pct:.2f} | {100 * prior * per_pct:.2f} / {width:.1f} | "
                  f"{100 * scatter:g} % | {rms:.2f} | {100 * equiv:.2f} % | {n1} | {n2} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
