"""The static method against the hammer on the twin (the paper's §2.5, Fig. 8): agreement and spread.

Runs ``protocols/static_combined.toml`` (roller type 1 on Ra 0.2 µm rails, 3 repetitions, at every step a static
reading and three hammer impacts) end to end through ``run_campaign`` for each seed, then prints per seed: the
largest |static − hammer| / σ over every step and repetition (σ: the two methods' independent σ in quadrature;
agreement means < 2), the ratio of the static to the hammer spread over the upper half of the loads, and the
coverage of the static σ against the twin's truth at each step's load (the fraction of |static − truth| < σ and
< 2σ; the truth is the roller's mean tangent stiffness from the hidden world at that load and seating — here
taken from the world's law, so seating scatter counts against the coverage). A last line gives, noise-free on the
default world's law, the bias of the local slope at the first three steps for the power law and for a parabola
through the same readings (why the power law is the local shape).

    python bench/static.py [--seeds 1 2 3]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from labctl.campaign import run_campaign
from labctl.physics.rig import roller_path_stiffness, roller_stiffness_from_path
from labctl.physics.rig_config import load_rig
from labctl.physics.world import load_world
from labctl.processing.static import local_slope, slope_weights
from labctl.protocol import load_protocol
from labctl.report.static_figure import compare

PROTOCOL = Path(__file__).resolve().parent.parent / "protocols" / "static_combined.toml"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    args = ap.parse_args()
    proto = load_protocol(PROTOCOL)
    law, case = load_world(None).law, proto.specimens[0].case()
    print(f"{'seed':>4} {'max|z|':>7} {'steps':>5} {'spread ratio (upper half)':>26} {'cover 1σ':>9} {'cover 2σ':>9}")
    for seed in args.seeds:
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "static.h5"
            run_campaign(proto, out=out, seed=seed)
            (c,) = compare(out)
        truth = np.vectorize(lambda p: float(law.stiffness_n_per_m(case, p)))(c.load_n)
        full_sigma = c.static_std_n_per_m  # independent σ (the K_setup share is exact on the twin's nominal rig)
        err = np.abs(c.static_n_per_m - truth) / full_sigma
        print(f"{seed:>4} {np.nanmax(np.abs(c.z)):7.2f} {c.step.size:5d} {c.upper_half_ratio():26.1f} "
              f"{np.mean(err < 1):9.2f} {np.mean(err < 2):9.2f}")

    noise_free_bias(law, case)


def noise_free_bias(law: object, case: object) -> None:
    """Relative error of the power-law and the parabola slope at steps 1-3 (half turns from the preload)."""
    rig = load_rig(None)
    ks = rig.setup_stiffness_n_per_m
    loads = rig.preload_per_roller_n + 180.0 * rig.load_per_knob_degree_n * np.arange(4)
    grid = np.linspace(loads[0], loads[-1], 40001)
    k = np.array([law.stiffness_n_per_m(case, p) for p in grid])  # type: ignore[attr-defined]
    compliance = 1.0 / roller_path_stiffness(k, ks)
    disp = np.interp(loads, grid, np.concatenate([[0.0], np.cumsum((compliance[1:] + compliance[:-1]) / 2
                                                                    * np.diff(grid))]))
    cells = []
    for i in range(3):
        start = max(i - 1, 0)
        x, y = loads[start:start + 3], disp[start:start + 3]
        truth = law.stiffness_n_per_m(case, loads[i])  # type: ignore[attr-defined]
        power = roller_stiffness_from_path(1.0 / local_slope(x, y, i - start)[0], ks) / truth - 1.0
        quad = roller_stiffness_from_path(1.0 / float(slope_weights(x, x[i - start]) @ y), ks) / truth - 1.0
        cells.append(f"step {i + 1} ({loads[i]:.0f} N): power law {power:+.2%}, parabola {quad:+.2%}")
    print("noise-free slope bias: " + "; ".join(cells))


if __name__ == "__main__":
    main()
