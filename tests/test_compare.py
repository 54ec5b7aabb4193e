"""``labctl compare``: the two-group test holds its level, finds real differences at the right loads, and reads
campaign files, stiffness tables and archive queries."""

from __future__ import annotations

import json

import numpy as np
import pytest

from labctl.cli import main
from labctl.compare import Curve, compare_groups, load_group
from labctl.compare.test import _holm
from labctl.errors import InputError
from labctl.stiffness_table import StiffnessPoint, write_stiffness_table

LOADS = np.linspace(40.0, 440.0, 9)


def _curves(rng, n: int, factor: float = 1.0, campaign: str = "c", scatter: float = 0.004) -> list[Curve]:
    out = []
    for _ in range(n):
        f = LOADS + rng.normal(0, 0.5, LOADS.size)
        k = 3e8 * np.log(f / 5.0) * factor * np.exp(rng.normal(0, scatter) + rng.normal(0, scatter, f.size))
        out.append(Curve("test", campaign, f, k))
    return out


def test_holm_matches_the_step_down_rule_by_hand():
    p = np.array([0.01, 0.04, 0.03, 0.005])
    # sorted 0.005, 0.01, 0.03, 0.04 → ×4, ×3, ×2, ×1 with running maximum: 0.02, 0.03, 0.06, 0.06
    assert _holm(p) == pytest.approx([0.03, 0.06, 0.06, 0.02])


def test_same_truth_is_no_difference_and_a_ten_percent_shift_is_found_at_every_load():
    rng = np.random.default_rng(3)
    same = compare_groups(_curves(rng, 3), _curves(rng, 3))
    assert not same.significant and same.unit == "repetition"
    shifted = compare_groups(_curves(rng, 3, factor=1.10), _curves(rng, 3))
    assert shifted.significant and len(shifted.significant_loads_n) == LOADS.size
    for d in shifted.loads:
        assert d.low < 0.10 < d.high and d.difference == pytest.approx(0.10, abs=0.02)


def test_a_difference_only_at_low_load_is_located_there():
    rng = np.random.default_rng(5)
    a = _curves(rng, 4)
    b = [Curve(c.source, c.campaign, c.load_n, c.stiffness_n_per_m * (1 + 0.3 * (40.0 / c.load_n) ** 3))
         for c in _curves(rng, 4)]
    result = compare_groups(a, b)
    assert result.loads[0].significant and not result.loads[-1].significant
    assert max(result.significant_loads_n) < 200.0


def test_the_null_level_holds_over_many_trials():
    rng = np.random.default_rng(11)
    hits = sum(compare_groups(_curves(rng, 3), _curves(rng, 3, scatter=0.006)).significant for _ in range(300))
    assert hits / 300 <= 0.05 + 2 * np.sqrt(0.05 * 0.95 / 300)


def test_campaign_unit_is_chosen_when_both_groups_hold_several_campaigns():
    rng = np.random.default_rng(2)
    a = _curves(rng, 3, campaign="a1") + _curves(rng, 3, campaign="a2")
    b = _curves(rng, 3, campaign="b1") + _curves(rng, 3, campaign="b2")
    result = compare_groups(a, b)
    assert result.unit == "campaign" and (result.replicates_a, result.replicates_b) == (2, 2)
    assert compare_groups(a, b, unit="repetition").replicates_a == 6


@pytest.mark.parametrize(("curves_a", "message"), [
    (1, "group A has 1 repetition"),
])
def test_too_few_replicates_is_a_clear_error(curves_a, message):
    rng = np.random.default_rng(1)
    with pytest.raises(InputError, match=message):
        compare_groups(_curves(rng, curves_a), _curves(rng, 3))


def test_groups_without_a_common_load_range_are_refused():
    rng = np.random.default_rng(1)
    low = [Curve("t", "c", c.load_n / 20.0, c.stiffness_n_per_m) for c in _curves(rng, 3)]
    with pytest.raises(InputError, match="share no load range"):
        compare_groups(low, _curves(rng, 3))


def _table(path, rng, factor: float, reps: int = 3) -> None:
    points = []
    for rep, c in enumerate(_curves(rng, reps, factor=factor), start=1):
        points += [StiffnessPoint(diameter_m=5e-3, contact_length_m=7.8e-3, rail_ra_m=0.2e-6, load_n=float(f),
                                  stiffness_n_per_m=float(k), roller_type=1, repetition=rep)
                   for f, k in zip(c.load_n, c.stiffness_n_per_m, strict=True)]
    write_stiffness_table(path, points)


def test_cli_on_stiffness_tables(tmp_path, capsys):
    rng = np.random.default_rng(8)
    _table(tmp_path / "a.csv", rng, 1.0)
    _table(tmp_path / "b.csv", rng, 1.0)
    _table(tmp_path / "c.csv", rng, 0.85)
    assert main(["compare", str(tmp_path / "a.csv"), str(tmp_path / "b.csv"), "--json"]) == 0
    same = json.loads(capsys.readouterr().out)
    assert same["significant"] is False and same["replicates_a"] == 3 and len(same["loads"]) == LOADS.size
    assert main(["compare", str(tmp_path / "a.csv"), str(tmp_path / "c.csv")]) == 0
    text = capsys.readouterr().out
    assert "significant difference at level 0.05" in text and "+17." in text  # 1/0.85 − 1 = +17.6 %


@pytest.mark.parametrize(("args", "message"), [
    (["nowhere.h5", "nowhere.h5"], "GROUP_A 'nowhere.h5': no such file or folder"),
    (["a.csv", "a.csv", "--level", "0.7"], "--level 0.7: expected a test level"),
    (["a.csv,a.csv", "a.csv"], "a file is named twice"),
])
def test_cli_bad_inputs_are_one_line_errors(tmp_path, capsys, monkeypatch, args, message):
    monkeypatch.chdir(tmp_path)
    _table(tmp_path / "a.csv", np.random.default_rng(1), 1.0)
    assert main(["compare", *args]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err


def test_twin_campaigns_same_rails_agree_and_other_rails_differ(tmp_path):
    from labctl.campaign import run_campaign
    from labctl.protocol import load_protocol

    # quick_check at three repetitions, on 0.8 s records (the response has died out by then)
    base = load_protocol("quick_check").source_text.replace("count = 1", "count = 3")
    assert "samples = 65536" in base
    base = base.replace("samples = 65536", "samples = 16384")
    for name, text in (("rough", base), ("smooth", base.replace("rail_ra_um = 0.2", "rail_ra_um = 0.03"))):
        (tmp_path / f"{name}.toml").write_text(text, encoding="utf-8")
    files = {}
    for name, protocol, seed in (("a", "rough", 1), ("b", "rough", 2), ("s", "smooth", 3)):
        files[name] = tmp_path / f"{name}.h5"
        run_campaign(tmp_path / f"{protocol}.toml", out=files[name], backend="sim", seed=seed)
    a, b, s = (load_group(str(files[n])) for n in "abs")
    assert len(a) == 3 and not compare_groups(a, b).significant
    rails = compare_groups(a, s)
    assert rails.significant and all(d.difference < 0 for d in rails.loads)  # smooth rails are stiffer
