"""Adaptive campaigns: the planner's extra load steps stay within the cap, the knob step and the budget, are
stored with their reason, are processed like any step, and an interrupted campaign resumes the stored plan."""

from __future__ import annotations

import json

import h5py
import pytest

from labctl import events as ev
from labctl.campaign import run_campaign
from labctl.discrepancy.synthetic import NoiseModel, synthesize
from labctl.engine import RunControl
from labctl.errors import InputError
from labctl.physics import ContactLaw, SurfaceRoughness, load_rig
from labctl.planning.adaptive import PlanAdvisor, knob_loads
from labctl.protocol import load_protocol
from tests.cli_util import labctl_here_json
from tests.engine_util import stepped_protocol_text


def _protocol(tmp_path, reps: int = 1):  # noqa: ANN001, ANN202
    path = tmp_path / "adaptive.toml"
    path.write_text(stepped_protocol_text("adaptive_short", roller_type=1, max_load=300.0, max_steps=3, reps=reps))
    return path


def _steps(path) -> list[dict]:  # noqa: ANN001
    with h5py.File(path, "r") as f:
        runs = f["series_01"]
        return [{"run": r, "step": s, **dict(runs[r][s].attrs)} for r in sorted(runs) if r.startswith("run_")
                for s in sorted(runs[r]) if s.startswith("step_")]


def test_adaptive_run_adds_planned_steps_within_cap_and_budget_and_process_reads_them(tmp_path, capsys):
    proto, out = _protocol(tmp_path), tmp_path / "a.h5"
    rig = load_rig()
    ran = labctl_here_json(capsys, "run", str(proto), "--out", str(out), "--seed", "3", "--world", "end_effects",
                           "--adaptive", "--budget-steps", "2")
    assert ran["status"] == "complete"
    steps = _steps(out)
    base = [s for s in steps if "added_by" not in s]
    added = [s for s in steps if s.get("added_by") == "plan"]
    assert len(base) == 3 and 1 <= len(added) <= 2
    per_deg = rig.load_per_knob_degree_n
    for s in added:
        assert s["knob_angle_deg"] % 90.0 == pytest.approx(0.0)
        assert rig.preload_per_roller_n + per_deg * s["knob_angle_deg"] <= 300.0 + 1e-9
        assert s["plan_reason"] and "type 1" in s["plan_reason"] and s["plan_score"] > 0
        assert s["load_n"] == pytest.approx(s["plan_load_n"], rel=0.05)  # the rig reached the planned load
    with h5py.File(out, "r") as f:
        stored = json.loads(f["series_01/run_01"].attrs["added_steps"])
    assert [a["angle_deg"] for a in stored] == [s["knob_angle_deg"] for s in added]
    done = labctl_here_json(capsys, "process", str(out))
    assert done["points"] == len(steps) == len(ran["runs"][0]["load_n"])


def test_interrupted_adaptive_campaign_resumes_the_stored_plan(tmp_path):
    proto, out = _protocol(tmp_path), tmp_path / "r.h5"
    control = RunControl()

    def stop_in_first_added_step(event: ev.Event) -> None:
        if isinstance(event, ev.StepProcessed) and event.position.step == 4:
            control.stop()

    first = run_campaign(proto, out=out, seed=5, world="end_effects", adaptive=True, budget_steps=2,
                         control=control, subscribers=[stop_in_first_added_step])
    assert first.status == "interrupted"
    with h5py.File(out, "r") as f:
        planned = f["series_01/run_01"].attrs["added_steps"]
    assert len(json.loads(planned)) == 2
    again = run_campaign(proto, out=out, resume=True)  # adaptive and its budget come from the file
    assert again.status == "complete"
    with h5py.File(out, "r") as f:
        assert f["series_01/run_01"].attrs["added_steps"] == planned
    added = [s for s in _steps(out) if s.get("added_by") == "plan"]
    assert [s["knob_angle_deg"] for s in added] == [a["angle_deg"] for a in json.loads(planned)]
    assert again.curves[0].load_n.size == 5


def test_advisor_candidates_are_the_mounted_specimens_knob_grid_below_its_cap(tmp_path):
    rig = load_rig()
    spec = load_protocol(_protocol(tmp_path)).specimens[0]
    loads = knob_loads(spec, rig)
    assert loads[0] == pytest.approx(rig.preload_per_roller_n) and loads[-1] <= spec.max_load_n
    assert loads.size == int((spec.max_load_n - rig.preload_per_roller_n) / (rig.load_per_knob_degree_n * 90)) + 1
    assert PlanAdvisor(rig).extra_steps([], spec, 3) == []


def test_advisor_repeats_the_most_informative_load(tmp_path):
    """Three points of a rough type-1 curve (preload to the top): the roughness parameter is pinned down at the
    preload, where the asperity layer dominates, so the planner repeats the preload step."""
    rig = load_rig()
    spec = load_protocol(_protocol(tmp_path)).specimens[0]

    def rough(case, load_n):  # noqa: ANN001, ANN202
        return ContactLaw("tripp", 1.5e-3, (SurfaceRoughness(3.0),)).stiffness_n_per_m(case, load_n)

    points = synthesize(rough, types=[1], noise=NoiseModel(0.02, 0.007), seed=1, repetitions=1, steps=3)
    added = PlanAdvisor(rig).extra_steps(points, spec, 3)
    angles = [a.angle_deg for a in added]
    assert len(angles) == 3 and len(set(angles)) < len(angles)
    assert angles.count(0.0) >= 2 and "surface_roughness" in added[0].reason


def test_adaptive_refuses_a_zero_budget_before_creating_a_file(tmp_path):
    proto, out = _protocol(tmp_path), tmp_path / "z.h5"
    with pytest.raises(InputError, match="budget-steps 0"):
        run_campaign(proto, out=out, adaptive=True, budget_steps=0)
    assert not out.exists()


def test_advisor_asks_for_a_second_level_above_an_onset_the_data_only_bracket(tmp_path):
    """A hardness onset at 310 N (type 1, gain 0.3, threshold 0.30) with one measured level above it (382 N):
    one linearisation at the best fit puts the onset just past the 281 N step and calls it determined; spread
    over the onsets the data still allow, the planner asks for loads between 281 N and the top, so that two
    levels lie above the onset."""
    import numpy as np

    from labctl.physics import MaterialHardness
    from labctl.stiffness_table import StiffnessPoint

    rig = load_rig()
    proto = tmp_path / "onset.toml"
    proto.write_text(stepped_protocol_text("onset", roller_type=1, max_load=400.0, max_steps=3, reps=2))
    spec = load_protocol(proto).specimens[0]
    case = spec.case()
    law = ContactLaw("tripp", 1.5e-3, (MaterialHardness(0.3, 0.30),))
    rng = np.random.default_rng(1)
    loads = {1: [37.9, 159.4, 280.9, 37.9, 37.9, 382.2], 2: [37.9, 159.4, 280.9]}
    points = []
    for rep, fs in loads.items():
        seat = 1e-3 * rng.standard_normal()
        for f in fs:
            k = float(law.stiffness_n_per_m(case, f)) * np.exp(seat + 3e-4 * rng.standard_normal())
            points.append(StiffnessPoint(case.roller.diameter_m, case.roller.contact_length_m, spec.rail_ra_m, f, k,
                                         roller_type=1, repetition=rep))
    added = PlanAdvisor(rig).extra_steps(points, spec, 3)
    above = {round(a.target_load_n) for a in added if a.target_load_n > 310.0}
    assert len(above - {382}) >= 1, [a.target_load_n for a in added]
