"""Twin speed bench: where the time of one simulated impact goes, beside a bare ``rfft`` of the same data.

One impact of a simulated campaign costs: the twin's synthesis of the record (``strike`` + ``record``: pulse,
modal superposition, noise, ADC), the automatic checks (``check_record``), the write into a campaign file
(``CampaignWriter.write_impact``) and a third of the identification of its step (``process_step`` on the step's
three impacts). Each is timed per impact (median over the impacts, CPU time of this process, so the machine's
load shows less) and printed as a multiple of one ``numpy.fft.rfft`` over the record's 13 channels, the floor
of any spectral synthesis of that record. A second reference line is the Gaussian draws the synthesis must make
for the sensors' noise (13 × samples normals from NumPy's generator): they are part of the record's data, so no
faster synthesis can skip them.

    python bench/twin_speed.py [--impacts 12] [--samples 65536] [--seed 1]

Run by hand (not a test).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from drivers.interfaces import TriggerSpec  # noqa: E402
from drivers.sim import twin_of  # noqa: E402
from labctl.backends import make_rig  # noqa: E402
from labctl.engine.steps import calibration_of  # noqa: E402
from labctl.physics.rig_config import load_rig  # noqa: E402
from labctl.protocol import load_protocol  # noqa: E402
from labctl.recording import check_record, process_step  # noqa: E402
from labctl.storage import CampaignWriter  # noqa: E402
from labctl.storage.specimen import SpecimenRecord  # noqa: E402

PROTOCOL = ROOT / "protocols" / "roller_stiffness.toml"
IMPACTS_PER_STEP = 3


def cpu_ms(fn: Callable[[], object]) -> tuple[float, object]:
    """CPU time of one call in ms, and what it returned."""
    t0 = time.process_time()
    out = fn()
    return (time.process_time() - t0) * 1e3, out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--impacts", type=int, default=12, help="impacts timed (a multiple of 3: whole steps)")
    ap.add_argument("--samples", type=int, default=None, help="record length (default: the protocol's)")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    proto = load_protocol(PROTOCOL)
    acq = proto.acquisition
    samples = args.samples or acq.samples
    rig = make_rig("sim", case=proto.specimens[0].case(), seed=args.seed)
    twin, rig_config = twin_of(rig), load_rig()
    twin.set_load_per_roller(200.0)
    trigger = TriggerSpec(acq.trigger_level_n, acq.pretrigger_samples)
    calibration = calibration_of(rig, rig_config.channels)
    steps = max(1, args.impacts // IMPACTS_PER_STEP)
    stages = ("rfft", "normal draws", "synthesis", "checks", "write", "identification")
    references = ("rfft", "normal draws")
    times: dict[str, list[float]] = {k: [] for k in stages}
    draws = np.random.default_rng(args.seed)
    twin.record(twin.strike(), acq.sample_rate_hz, samples, trigger)  # warm caches (frequency grid, imports)
    with tempfile.TemporaryDirectory() as tmp:
        writer = CampaignWriter.create(Path(tmp) / "bench.h5", protocol_name="bench", backend="sim", seed=args.seed,
                                       config_files={}, description={})
        with writer:
            writer.series(1, SpecimenRecord(label="bench"))
            writer.run(1, 1)
            for step in range(1, steps + 1):
                writer.step(1, 1, step, {"load_n": 200.0})
                held = []
                for attempt in range(1, IMPACTS_PER_STEP + 1):
                    ms, record = cpu_ms(lambda: twin.record(twin.strike(), acq.sample_rate_hz, samples, trigger))
                    times["synthesis"].append(ms)
                    data = np.vstack([record.force_n[None, :], record.accel_m_per_s2])
                    times["rfft"].append(cpu_ms(lambda d=data: np.fft.rfft(d, axis=1))[0])
                    times["normal draws"].append(cpu_ms(lambda d=data: draws.standard_normal(d.shape))[0])
                    ms, impact = cpu_ms(lambda r=record, a=attempt: check_record(r, a, proto.checks, calibration))
                    times["checks"].append(ms)
                    ms, stored = cpu_ms(lambda s=step, i=impact: writer.write_impact(1, 1, s, i))
                    times["write"].append(ms)
                    held.append(stored)
                ms, result = cpu_ms(lambda h=held: process_step(h, rig_config, proto.checks))
                if not result.identified:
                    raise RuntimeError(f"step {step} was not identified: {result.error}")
                times["identification"].extend([ms / IMPACTS_PER_STEP] * IMPACTS_PER_STEP)
    med = {k: statistics.median(v) for k, v in times.items()}
    total = sum(v for k, v in med.items() if k not in references)
    print(f"{steps * IMPACTS_PER_STEP} simulated impacts of 13 channels × {samples} samples "
          f"(median CPU ms per impact; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs)")
    print(f"{'stage':<16} {'ms':>8} {'× rfft':>8} {'share':>7}")
    for k in stages:
        share = "" if k in references else f"{med[k] / total:7.0%}"
        print(f"{k:<16} {med[k]:8.2f} {med[k] / med['rfft']:8.1f} {share}")
    print(f"{'impact total':<16} {total:8.2f} {total / med['rfft']:8.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
