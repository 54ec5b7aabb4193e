"""Storage bench: MB per impact and ms to write one impact, schema 1 (float32, uncompressed) against schema 2
(ADC counts with the scale-offset filter), on records of the simulated rig (the demo's 65 536 samples).

    python bench/storage.py [N_IMPACTS]

Run by hand (not a test). Times are medians over the impacts; the machine's load shows in them.
"""

from __future__ import annotations

import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np

from drivers.interfaces import TriggerSpec
from labctl.backends import make_rig
from labctl.engine.steps import calibration_of
from labctl.protocol import load_protocol
from labctl.recording import check_record
from labctl.storage import CampaignWriter
from labctl.storage.specimen import SpecimenRecord


def records(n: int) -> tuple[list, object]:
    proto = load_protocol(Path(__file__).resolve().parents[1] / "protocols" / "roller_stiffness.toml")
    acq = proto.acquisition
    rig = make_rig("sim", case=proto.specimens[0].case(), seed=1)
    out = []
    with rig.daq, rig.hammer:
        rig.daq.configure(acq.sample_rate_hz, acq.samples)
        for _ in range(n):
            rig.daq.arm(TriggerSpec(acq.trigger_level_n, acq.pretrigger_samples))
            rig.hammer.strike()
            out.append(rig.daq.acquire(5.0))
    return out, proto


def _clock() -> tuple[float, float]:
    return time.perf_counter(), time.process_time()


def _since(t: tuple[float, float]) -> tuple[float, float]:
    return time.perf_counter() - t[0], time.process_time() - t[1]


def write_v1(path: Path, recs: list) -> list[tuple[float, float]]:
    """The schema-1 writer's datasets: float32, accel chunked by channel, no filter; flushed per impact."""
    times = []
    with h5py.File(path, "w") as h5:
        step = h5.create_group("series_01/run_01/step_001")
        for i, r in enumerate(recs, start=1):
            t = _clock()
            g = step.create_group(f"impact_{i:03d}")
            g.create_dataset("force_n", data=np.asarray(r.force_n, dtype=np.float32))
            g.create_dataset("accel_m_per_s2", data=np.asarray(r.accel_m_per_s2, dtype=np.float32),
                             chunks=(1, r.accel_m_per_s2.shape[-1]))
            g.attrs.update({"attempt": i, "accepted": True, "reasons": "[]", "peak_force_n": 250.0,
                            "pulse_width_s": 3e-4, "sample_rate_hz": r.sample_rate_hz, "trigger_index": 256,
                            "timestamp_utc": "2026-01-01T00:00:00.000+00:00", "clipped": "[]"})
            g["force_n"].attrs.update({"unit": "N", "sensitivity_v_per_unit": 0.23e-3, "range_units": 22240.0})
            g["accel_m_per_s2"].attrs.update({"unit": "m/s^2", "channels": '["A1X"]',
                                              "sensitivity_v_per_unit": [0.01] * 12, "range_units": [490.0] * 12})
            g.attrs["complete"] = True  # the schema-1 writer's attributes, so both columns pay for them
            h5.flush()
            times.append(_since(t))
    return times


def write_v2(path: Path, recs: list, rig: object, proto: object) -> list[tuple[float, float]]:
    times = []
    with CampaignWriter.create(path, protocol_name="bench", backend="sim", seed=None, config_files={},
                               description={}) as w:
        w.series(1, SpecimenRecord(label="bench"))
        w.run(1, 1)
        w.step(1, 1, 1, {"load_n": 0.0})
        for i, r in enumerate(recs, start=1):
            impact = check_record(r, i, proto.checks, calibration_of(rig, r.channels))  # type: ignore[attr-defined]
            t = _clock()
            w.write_impact(1, 1, 1, impact)
            times.append(_since(t))
    return times


def main(n: int = 10) -> int:
    recs, proto = records(n)
    rig = make_rig("sim", case=proto.specimens[0].case(), seed=1)  # type: ignore[attr-defined]
    with tempfile.TemporaryDirectory() as tmp:
        p1, p2 = Path(tmp) / "v1.h5", Path(tmp) / "v2.h5"
        t1, t2 = write_v1(p1, recs), write_v2(p2, recs, rig, proto)
        mb1, mb2 = os.path.getsize(p1) / n / 1e6, os.path.getsize(p2) / n / 1e6
    print(f"{n} impacts of {recs[0].accel_m_per_s2.shape[0] + 1} channels × {recs[0].force_n.size} samples")
    for name, mb, t in (("schema 1 (float32, no filter)      ", mb1, t1),
                        ("schema 2 (ADC counts, scale-offset)", mb2, t2)):
        wall, cpu = (statistics.median(x[i] for x in t) * 1e3 for i in (0, 1))
        print(f"{name}: {mb:6.3f} MB/impact  write {wall:6.1f} ms wall, {cpu:6.1f} ms CPU")
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
    print(f"ratio {mb1 / mb2:.2f}×")
    return 0


if __name__ == "__main__":
    sys.exit(main(*(int(a) for a in sys.argv[1:])))
